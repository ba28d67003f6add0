"""What a study is, for every side: its config, its bank, and a trial's payload, clicks, rows."""
