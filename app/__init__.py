"""tomstudy: worlds, models and the online study of how people predict a robot."""

__version__ = "0.1.0"
