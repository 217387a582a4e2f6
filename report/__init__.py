"""Reports from a recorded run: measures, summary.json, figures, report.md."""
