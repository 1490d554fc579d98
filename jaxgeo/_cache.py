"""The persistent XLA compilation cache, in one call.

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
