"""Developer tools run from the repository root: the module tree, the import graph, world
branches and the refactor fingerprint (`python -m tools.<name>`); tests use some of them."""
