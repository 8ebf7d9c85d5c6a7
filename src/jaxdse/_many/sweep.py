"""Configurations for hyperparameter sweeps: grids and log-uniform random draws."""

from __future__ import annotations

import itertools

import numpy as np

from .._core.drem import ObserverConfig
from .batch import stack


def _expand(name: str, value: float) -> dict[str, float]:
    return {"gamma1": value, "gamma2": value} if name == "gamma" else {name: value}


def sweep_configs(base: ObserverConfig, parameters: dict[str, list[float]], mode: str = "grid",
                  draws: int = 64, seed: int = 0) -> tuple[ObserverConfig, list[dict[str, float]]]:
    """A stacked batch of configurations around ``base`` and the values of each member.

    Arguments:
        parameters: name -> values (``mode="grid"``: every combination) or name -> [low, high]
            (``mode="random"``: ``draws`` log-uniform draws). "gamma" sets gamma1 = gamma2.

    Returns:
        (configurations with a leading batch axis, one dict of swept values per member).
    """
    names = list(parameters)
    if mode == "grid":
        points = [dict(zip(names, combo)) for combo in itertools.product(*parameters.values())]
    elif mode == "random":
        rng = np.random.default_rng(seed)
        lows = np.log([parameters[n][0] for n in names])
        highs = np.log([parameters[n][1] for n in names])
        points = [dict(zip(names, np.exp(rng.uniform(lows, highs)).tolist())) for _ in range(draws)]
    else:
        raise ValueError(f"mode must be 'grid' or 'random', got {mode!r}")
    configs = []
    for p in points or [{}]:
        values = {k: v for n, x in p.items() for k, v in _expand(n, float(x)).items()}
        configs.append(ObserverConfig(**{**{f: getattr(base, f) for f in base.__dataclass_fields__},
                                         **values}))
    return stack(configs), points or [{}]
