"""The INTERACTION experiment: the paper's real-data test on recorded (or generated) driving.

tracks.py reads the files, pairs.py cuts robot/human pairs, lanelet_map.py reads the map,
synthetic.py writes generated (not real) files, dataset.py turns pairs into trajectories and
windows, experiment.py trains, scores and tests, horizons.py holds the secondary horizons,
codes.py chooses Ours' levels and scores its codes against the manoeuvres, report.py draws
and writes the report.
"""
