"""One generator, one configuration: the pure, jit/vmap/grad-compatible pipeline.

Stages in pipeline order: ``recording`` (and ``sequence``) -> ``mapping`` -> ``algebraic``
(with ``machine``) -> ``signals`` -> ``governor`` -> ``drem`` (on ``integrate``) ->
``playback`` -> ``metrics``; ``front_end`` chains the per-sample stages, ``estimate``
orchestrates them and ``result`` builds the :class:`Estimate`. ``plant`` and ``settings``
hold the shared parameter types, ``xla`` small helpers (the blocks and parameter checks that
the standard models share are in ``jaxdse._base``).
"""
