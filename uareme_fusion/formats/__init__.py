"""File formats, each read and written in one module (drivers, the simulator and the sinks import
them; they import nothing above `io`):

- `tum`: TUM RGB-D lists, associations, trajectories (`t tx ty tz qx qy qz qw`) and accelerometer files;
- `euroc`: EuRoC MAV IMU (`imu0/data.csv`) and ground-truth CSVs;
- `broad`: BROAD trials (HDF5: IMU with optical reference);
- `ground_truth`: a TUM or EuRoC trajectory file as the camera's `R_wc` (`eval --gt FILE`);
- `depth_png`: 16-bit depth PNGs and their units;
- `datasets`: published intrinsics and frame conventions of ICL-NUIM, ICSL and TUM RGB-D;
- `images`: colour images as RGB arrays.
"""
