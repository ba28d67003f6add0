"""The INTERACTION experiment: the paper's real-data test on recorded (or generated) driving.

The recorded data is read by app/recordings/ (tracks.py the files, pairs.py the robot/human
pairs, lanelet_map.py the map, synthetic_tracks.py generated, not real, files); here
dataset.py turns pairs into trajectories and windows, experiment.py trains, scores and
tests, horizons.py holds the secondary horizons, codes.py chooses Ours' levels and scores
its codes against the manoeuvres, report.py draws and writes the report.
"""
