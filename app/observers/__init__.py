"""Simulated participants: observer presets that click like people, and the in-process
studies (power, instrument check) that run them on a trial bank."""
