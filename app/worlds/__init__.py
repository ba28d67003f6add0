"""The two simulated worlds (Highway, Obstacle) behind one `World` protocol."""
