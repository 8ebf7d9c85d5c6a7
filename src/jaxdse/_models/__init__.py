"""The standard PSS/E dynamic models, one family a module: machines, exciters (by IEEE Std
421.5 type), stabilisers and governors, with their interfaces (``base``). The estimator takes
its governor-turbine models from here; the .dyr playback composes all of them per unit."""
