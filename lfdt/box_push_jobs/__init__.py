"""Per-configuration jobs of the matrix stages (one module per kind of job)."""
