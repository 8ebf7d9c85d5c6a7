"""Live PMU streams, IEEE C37.118.2-2011 (pure Python and NumPy, no JAX in the codec).

``c37118``  the codec: configuration (CFG-1, CFG-2, CFG-3 with its CONT_IDX fragments), data,
            header and command frames, encoded and decoded byte for byte (round trip exact);
            the STAT word and the FRACSEC time-quality byte; CRC-CCITT; a decoder that takes
            a byte stream incrementally and yields frames (:class:`~.c37118.StreamDecoder`),
            and rejects a malformed frame with an exception type that says why
            (:class:`~.c37118.FrameError` and its subclasses), never with a crash or an
            allocation beyond the frame's 65535 bytes.
``pmu_sim`` a loopback PMU: ``jaxdse pmu-sim``. Serves any recording jaxdse reads (a run
            configuration's generators, or a fleet file's plants) as PMU stations of one
            concentrator, on the reporting grid of the recording's time axis, over TCP (the
            standard's command frames) or UDP, with fault injection; and
            :class:`~.pmu_sim.PmuClient`, a small blocking client (connect, request the
            configuration, turn transmission on and off, read frames).

A monitor uses them as: ``pmu = PmuClient(host, port, idcode)``, ``cfg = pmu.config()``
(CFG-2), ``pmu.start()``, then ``for frame in pmu.frames(...)`` (or its own socket loop feeding
:class:`~.c37118.StreamDecoder`); ``frame.arrays`` holds every station's STAT, phasors, FREQ
and DFREQ as arrays (decoded in one pass: 0.4 ms for a 500-station frame), and
:func:`~.c37118.grid_index` places the frame on the reporting grid by its timestamp, never by
its arrival time. :func:`~.pmu_sim.served_units` says how the simulator's phasors convert
back to per unit.
"""
