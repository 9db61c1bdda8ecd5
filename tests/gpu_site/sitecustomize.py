"""Put on ``PYTHONPATH`` by ``tests/gpu_image.py``: the packages named in ``JAXTERRAIN_TEST_MISSING`` (commas) cannot
be imported in this process, as on the GPU machine's image."""

import os
import sys

for _name in filter(None, os.environ.get("JAXTERRAIN_TEST_MISSING", "").split(",")):
    sys.modules[_name] = None  # `import name` and `from name import x` raise ModuleNotFoundError
