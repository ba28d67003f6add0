"""Analysis of exported study data: alignment metrics, tests, figures, reports.

Depends on nothing in `app` but its foundations, `app/core/` (the export contracts, alignment
error, file writing): a researcher can read exports with these two alone."""
