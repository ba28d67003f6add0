"""A study's preregistration (`tomstudy prereg`), written from its config, its frozen bundle and
the instrument's and power simulation's results, every number with the file it came from."""
