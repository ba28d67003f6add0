"""The server's storage room: the tables, the engine, schema migrations and the transactions."""
