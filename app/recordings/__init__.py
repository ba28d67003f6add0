"""Recorded two-agent interactions: every reader of recorded data and the recorded world.

The INTERACTION track files (tracks.py), their lanelet2 maps (lanelet_map.py), a lab's own
CSV logs (csv_logs.py) and generated, not real, files in both formats (synthetic_tracks.py,
generated.py, synthetic_logs.py) are read into recordings and cut into robot/human pairs
(pairs.py); importer.py turns a recorded world's recordings into its trajectory file."""
