"""HTTP routes: participant API, researcher API and dashboard, HTML pages."""
