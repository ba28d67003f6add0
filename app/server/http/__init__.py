"""The server's HTTP room: the routes, their dependencies, wire bodies, headers and limits."""
