import jax

jax.config.update("jax_enable_x64", True)

# Hypothesis profiles for tests/test_properties.py: "ci" (default) keeps the suite
# inside the CI budget (≥ 200 generated cases in all); "long" is for runs by hand:
#   HYPOTHESIS_PROFILE=long pytest tests/test_properties.py
import os  # noqa: E402

from hypothesis import settings  # noqa: E402

settings.register_profile("ci", max_examples=90, deadline=None, derandomize=True)
settings.register_profile("long", max_examples=2000, deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))
