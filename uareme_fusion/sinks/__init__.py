"""Where a run's results go, one `write(FrameResult)` (and `close()`) each: the estimate tables
(`estimate_files`: estimates.csv, the TUM trajectory, the in-memory log), overlay videos and images
(`drawing`), a Foxglove MCAP file (`mcap_file`) and a rerun recording (`rerun_file`)."""
