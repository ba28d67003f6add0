"""The INTERACTION experiment: the paper's real-data test on recorded (or generated) driving.

tracks.py reads the files, pairs.py cuts robot/human pairs, lanelet_map.py reads the map,
synthetic.py writes generated (not real) files, dataset.py turns pairs into trajectories and
windows, experiment.py trains, scores and tests, report.py draws and writes the report.
"""
