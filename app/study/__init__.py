"""The study server: trial bank, participant flow, storage, researcher side, pilot bots."""
