"""The server's session flow: plans, sessions, steps, answers, places, balance and endings."""
