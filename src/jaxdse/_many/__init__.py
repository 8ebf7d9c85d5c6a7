"""Many runs at once: batches (``batch``), long recordings in chunks (``stream``),
configuration sweeps (``sweep``) and gradient-based tuning (``tune``)."""
