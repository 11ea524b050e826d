"""A trunk fitted to a musculoskeletal model's skeleton: the abdomen-diaphragm membrane and
the thoracic cavity built from its rib cage, spine and pelvis (`fit_trunk`; the command
`hybrid anatomy`)."""

from .fit import TrunkFit, fit_trunk

__all__ = ["TrunkFit", "fit_trunk"]
