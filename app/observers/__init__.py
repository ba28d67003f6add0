"""Simulated participants: observers that click like people, and studies run on them in process."""
