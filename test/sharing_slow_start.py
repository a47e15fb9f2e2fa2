"""A module slow to import: a helper importing it is still starting when a share begins."""

import time

time.sleep(2.0)
