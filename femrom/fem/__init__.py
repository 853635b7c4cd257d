"""Finite-element forms, assembly, boundary conditions, loads and outputs."""

from femrom.fem._condensation import Condensation
from femrom.fem._damping import rayleigh_damping, rayleigh_from_damping_ratios
from femrom.fem._line import (
    axial_stiffness,
    bending_stiffness,
    hrz_lumped,
    line_basis,
    line_mass,
)
from femrom.fem._nonlinear import LocalPotential, NonlinearForce

__all__ = [
    "Condensation", "LocalPotential", "NonlinearForce", "axial_stiffness", "bending_stiffness",
    "hrz_lumped", "line_basis", "line_mass", "rayleigh_damping", "rayleigh_from_damping_ratios",
]
