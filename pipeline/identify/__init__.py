"""Section 4 of Masoud & Maas 2025: the physics-informed RBF model and its identification."""

from pipeline.identify.basis import RBFBasis
from pipeline.identify.config import IdentifyConfig
from pipeline.identify.fit import FitDiagnostics, Record, fit_rbf_model
from pipeline.identify.model import RBFModel

__all__ = ["FitDiagnostics", "IdentifyConfig", "RBFBasis", "RBFModel", "Record", "fit_rbf_model"]
