"""The researcher side: dashboard, exports, replay, withdrawal and progress (served behind the
token by app/http/routes)."""
