"""jaxmech benchmarks: one script per question, JSON results in ``results/``, a summary table."""
