"""HTTP routes of the participant side: the participant API and the HTML pages."""
