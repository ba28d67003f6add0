"""The participant server: session flow, storage, validation, recruitment and endings."""
