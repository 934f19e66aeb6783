"""DoorKey: fetch the key, unlock the door in the wall, reach the coloured goal; avoid lava.

Only this package imports minigrid (through objects.py); `import sim` does not.
"""

import os

# minigrid imports pygame, which greets on stdout unless told not to.
os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
