from typing import Any, Dict, Optional

from ._camsim import *  # noqa: F401,F403
from ._camsim import Camera

__version__: str

def camera(name: Optional[str] = None, *, optics: Optional[Dict[str, Any]] = None,
           sensor: Optional[Dict[str, Any]] = None, **params: Any) -> Camera:
    """A camera from keyword parameters (camera.json keys; optics keys go to optics)."""
