"""A study's trial bank, offline: built from held-out data, frozen into a bundle, verified."""
