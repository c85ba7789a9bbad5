from .report.base import Finding, ReportContext, Section  # noqa: F401  shim until cli/ merge (the lead deletes it)
