"""Every HTTP route of the study: the participant API, the HTML pages, and the researcher API
and dashboard behind the bearer token."""
