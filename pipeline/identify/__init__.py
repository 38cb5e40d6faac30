"""Section 4 of Masoud & Maas 2025: the physics-informed RBF model and its identification."""

from debist.identify.config import IdentifyConfig
from debist.identify.fit import FitDiagnostics, Record, fit_rbf_model
from debist.model.basis import RBFBasis
from debist.model.rbf import RBFModel

__all__ = ["FitDiagnostics", "IdentifyConfig", "RBFBasis", "RBFModel", "Record", "fit_rbf_model"]
