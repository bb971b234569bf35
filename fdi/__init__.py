"""fdi: estimators and fault detectors of fdi-bridge (pure algorithms, no I/O)."""
