"""The researcher side: dashboard, exports, replay, withdrawal and progress (behind the token)."""
