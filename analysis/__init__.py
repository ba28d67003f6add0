"""Analysis of exported study data: contracts, alignment metrics, tests, figures, reports.

Depends on nothing in `app`: a researcher can read exports with it alone."""
