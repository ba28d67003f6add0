"""What a study is, for every side: its typed config, its trial bank and its write-path error."""
