"""Offline analysis of records: model-to-model errors and (with issue 5) the report's test results."""
