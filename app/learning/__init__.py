"""Ours (FSQ autoencoder) and the VAE: networks, training, checkpoints, fields, selection."""
