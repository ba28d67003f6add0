"""Predictors: anything that reads a trial's history and answers the robot's next moves.

protocol.py says what a predictor is; builtin.py wraps the study's checkpoints (Ours, the VAE)
and constant velocity in it; ctrv.py is a plug-in registered like a lab's own; registry.py
finds plug-ins by name through Python entry points (group `tomstudy.predictors`).
"""
