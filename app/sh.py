"""Moved to app/twins/sh.py. Kept only for app/render/probes.py's import (the probe bake, being
reworked on another branch); delete this file once that import reads ``from ..twins.sh``."""
from .twins.sh import sh_band_factors

__all__ = ["sh_band_factors"]
