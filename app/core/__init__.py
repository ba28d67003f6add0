"""Foundations both `app` and `analysis` build on, importing neither: alignment error, the
export contracts and exclusion rules, spreadsheet-safe CSV, file writing and hashing, scenes
drawn from their JSON."""
