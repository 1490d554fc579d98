"""`python -m jaxgeo.data`: rewrite the example meshes from their generators."""

from . import write_examples

for path in write_examples():
    print(path)
