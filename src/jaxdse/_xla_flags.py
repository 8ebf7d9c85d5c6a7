"""XLA flags the package needs, set before JAX's CPU backend starts (imported first).

XLA's multi-threaded Eigen pool can wedge on vmapped graphs of small solves (the batch
identification's bootstrap): runs hung, idle, after compiling. Single-threaded Eigen avoids
it; the batch axis still runs in parallel. The flag is read when the CPU backend starts, so it
holds whenever jaxdse is imported before the first computation; set it yourself to override.
"""

import os

_flags = os.environ.get("XLA_FLAGS", "")
if "xla_cpu_multi_thread_eigen" not in _flags:
    os.environ["XLA_FLAGS"] = f"{_flags} --xla_cpu_multi_thread_eigen=false".strip()
