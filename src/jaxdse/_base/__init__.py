"""The lowest layer: the transfer-function blocks (``blocks``) and the parameter checks
(``fields``) that the standard models (``_models``) and the estimator (``_core``) share. It
imports nothing of jaxdse, so both stand above it."""
