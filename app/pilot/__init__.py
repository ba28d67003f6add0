"""Pilot participants: bots that take a study over HTTP as a browser would."""
