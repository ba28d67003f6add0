"""Recorded two-agent interactions: a lab's own CSV logs and the INTERACTION track files,
read into recordings and cut into robot/human pairs."""
