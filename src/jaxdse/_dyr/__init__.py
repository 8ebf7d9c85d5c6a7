"""The planner's own model: PSS/E machine, exciter, stabiliser and governor records as equinox
modules, played back against a recording, ranked by sensitivity and calibrated."""
