"""The study's server behind the web layer: session flow, storage, the wire bodies, and the
queries the researcher side reads."""
