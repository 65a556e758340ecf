"""Running backends on sequences and scoring them: the sequences they run on (`sequence`,
`source_sequence`), the backend comparison (`compare`), paired differences (`paired_difference`) and the
simulated scenarios of the EKF benchmark (`scenarios`). The pure metrics and statistics are in `scoring`,
the backends by name in `backends.factory`; commands (`eval`, `compare`, `bench`, `demo`) live in `cli`."""
