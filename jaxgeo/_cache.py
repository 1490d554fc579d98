"""Process-wide settings the command line turns on: the persistent XLA
compilation cache, in one call, and one BLAS thread (`limit_blas_threads`).

jaxgeo's solvers take 15-60 s to compile per mesh size and method; JAX can keep
the compiled code on disk so that the next process reuses it. The command line
turns this on always; from Python call `jaxgeo.enable_compilation_cache()`.

It is off by default for a library: the setting is global to the process (it
changes the caching of the user's own jitted functions too), it writes to the
user's home directory, which a library should not do unasked, and JAX never
evicts entries (the directory grows with every new mesh size and option set;
delete it to reclaim the space).
"""

from __future__ import annotations

import os

#: Where the command line and `enable_compilation_cache()` keep compiled code
#: unless `JAX_COMPILATION_CACHE_DIR` says otherwise.
DEFAULT_CACHE_DIR = os.path.join(os.path.expanduser("~"), ".cache", "jaxgeo", "xla")


def enable_compilation_cache(path: str | os.PathLike | None = None) -> str:
    """Keep JIT-compiled code on disk so later processes skip the compilation.

    **Arguments:**

    - `path`: the cache directory; default `$JAX_COMPILATION_CACHE_DIR`, else
      `~/.cache/jaxgeo/xla` (the command line's). Created if missing.

    Call it once, best before the first computation (compilations before it are
    not stored). It sets JAX's `jax_compilation_cache_dir` for the whole process.
    The cache is trusted code: do not point it at a directory others can write.

    **Returns:** the directory used.
    """
    import jax
    from jax.experimental.compilation_cache import compilation_cache

    if path is None:
        path = os.environ.get("JAX_COMPILATION_CACHE_DIR") or DEFAULT_CACHE_DIR
    path = os.path.abspath(os.path.expanduser(os.fspath(path)))
    os.makedirs(path, exist_ok=True)
    # (JAX's flags are attributes that jax.config sets at run time)
    if jax.config.jax_compilation_cache_dir != path:  # pyright: ignore[reportAttributeAccessIssue]
        jax.config.update("jax_compilation_cache_dir", path)
        # JAX opens its cache once, at the first compilation: start over so that a
        # call after some compilations (or with a new path) takes effect.
        compilation_cache.reset_cache()
    return path


#: the variables that, when set by the user, leave the BLAS threads alone
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")


def limit_blas_threads() -> int:
    """One BLAS thread for this process, unless the user chose: a no-op when
    `OPENBLAS_NUM_THREADS` or `OMP_NUM_THREADS` is set.

    jaxlib's batched LAPACK calls (the banded flattening's Cholesky and
    triangular solves, `cutting.objective`) run in scipy's OpenBLAS, whose
    threads spin against other processes on a busy or small CPU (one
    factorisation of the twin-peak tent's cloths: 0.44-1.6 s with the default
    threads, 45 ms with one; `docs/cutting.md`). OpenBLAS reads the variable
    only when it is loaded, and `import jaxgeo` has loaded it (numpy, scipy)
    before any command runs: so this sets `OPENBLAS_NUM_THREADS=1` for child
    processes and limits every BLAS already loaded with `threadpoolctl`. A
    library user sets the variable before importing numpy, scipy or jax, or
    calls `threadpoolctl.threadpool_limits(1, user_api="blas")`.

    **Returns:** how many loaded BLAS libraries were limited.
    """
    if any(v in os.environ for v in BLAS_THREAD_VARIABLES):
        return 0
    from threadpoolctl import ThreadpoolController

    os.environ["OPENBLAS_NUM_THREADS"] = "1"
    blas = ThreadpoolController().select(user_api="blas")
    blas.limit(limits=1)
    return len(blas.lib_controllers)
