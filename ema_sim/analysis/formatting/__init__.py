"""What every section-2 test's plots and Markdown share: the Agg figure helpers and the Markdown helpers."""
