"""The names of the light domains (model.md §13), importable without torch (command-line
parsers list them as choices).

- ``srgb``: the paper's protocol. A scene's 8-bit sRGB values divided by 255 are the light the
  sensor sees; reconstructions are scored on the same values.
- ``linear``: scenes are decoded to linear radiance with the sRGB transfer function before the
  sensor and the noise; reconstructions estimate radiance and are encoded back to 8-bit sRGB
  before scoring (:mod:`splitcam.physics.light`).
"""

from __future__ import annotations

__all__ = ["DEFAULT_DOMAIN", "DOMAINS", "LINEAR", "SRGB"]

#: The paper's protocol: 8-bit sRGB values / 255 are the light.
SRGB = "srgb"
#: Linear radiance, decoded from sRGB (photon-limited work).
LINEAR = "linear"
#: The light domains, the paper's first.
DOMAINS = (SRGB, LINEAR)
#: The paper's protocol.
DEFAULT_DOMAIN = SRGB
