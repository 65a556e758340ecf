"""Scoring estimates against ground truth, in the manner of evo's core: pure metrics and statistics
(`metrics`, `statistics`), the backends by name (`backend_factory`), the sequences they run on
(`sequence`, `source_sequence`), the backend comparison (`compare`) and the simulated scenarios of
the EKF benchmark (`scenarios`). Commands (`eval`, `compare`, `bench`, `demo`) live in `cli`."""
