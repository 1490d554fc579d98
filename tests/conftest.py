import os
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

# A persistent XLA compilation cache shared by the test process and the processes
# it starts (notebook kernels, the sharding subprocess): JIT compiles dominate the
# suite's time, and a second compile of the same function then costs a file read.
_CACHE = str(Path(__file__).resolve().parent.parent / ".jax_cache")
os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", _CACHE)
jax.config.update("jax_compilation_cache_dir", os.environ["JAX_COMPILATION_CACHE_DIR"])

# Hypothesis profiles for tests/test_properties.py: "ci" (default) keeps the suite
# inside the CI budget (≥ 200 generated cases in all); "long" is for runs by hand:
#   HYPOTHESIS_PROFILE=long pytest tests/test_properties.py
from hypothesis import settings  # noqa: E402

settings.register_profile("ci", max_examples=90, deadline=None, derandomize=True)
settings.register_profile("long", max_examples=2000, deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


# jaxtyping's import hook (pyproject's addopts: --jaxtyping-packages) checks every
# call into jaxgeo against its annotations. Tests marked `mistyped` pass arguments
# of the wrong type on purpose, to test the error a user gets; the check would
# reject them first, so it is off during those tests.
import jaxtyping  # noqa: E402
import pytest  # noqa: E402


@pytest.fixture(autouse=True)
def _type_checks_off_if_mistyped(request):
    if request.node.get_closest_marker("mistyped") is None:
        yield
        return
    before = jaxtyping.config.jaxtyping_disable
    jaxtyping.config.update("jaxtyping_disable", True)
    try:
        yield
    finally:
        jaxtyping.config.update("jaxtyping_disable", before)
