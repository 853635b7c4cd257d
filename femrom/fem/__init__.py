"""Finite-element forms, assembly, boundary conditions, loads, outputs and nonlinear forces.

Materials are one isotropic material (floats) or :class:`ElementMaterial`, constants per
element (several materials by region); outputs include the row averaging a displacement
component over the nodes nearest to a point (:func:`nearest_node_rows`).
"""

from femrom.fem._condensation import Condensation
from femrom.fem._constraints import dirichlet_dofs, rigid_body_modes
from femrom.fem._damping import rayleigh_damping, rayleigh_from_damping_ratios
from femrom.fem._elasticity import elasticity_stiffness, lame_parameters, vector_mass
from femrom.fem._material import ElementMaterial
from femrom.fem._line import (
    axial_stiffness,
    bending_stiffness,
    hrz_lumped,
    line_basis,
    line_mass,
)
from femrom.fem._friction import JenkinsForce
from femrom.fem._interface_law import (
    INTERFACE_LAWS,
    InterfaceLaw,
    ParallelSliderLaw,
    interface_law,
    interface_law_from_parameters,
    radial_return,
    slider_return,
    register_interface_law,
)
from femrom.fem._law_kernels import (CompiledJoint, CompiledScalar, CompiledSliders, compiled_kernels, compiled_laws,
                                    compiled_scalar_kernels, use_compiled_laws)
from femrom.fem._joint import JointForce, interface_frames, relative_displacement_map
from femrom.fem._loads import point_load, surface_pressure, surface_traction
from femrom.fem._outputs import average_rows, nearest_node_rows, probe_rows
from femrom.fem._nonlinear import (
    FORCES,
    ForceSum,
    NonlinearForce,
    force_from_parameters,
    register_force,
    selection_map,
    sum_of_forces,
)
from femrom.fem._transformed_force import TransformedForce, dense_projection, transform_force
from femrom.fem._potentials import DENSITIES, LocalPotential, QuarticPotential
from femrom.fem._spaces import LineSpace, SolidSpace, SpaceError
from femrom.fem.interface_laws.clamped_friction import ClampedFrictionLaw, clamped_state
from femrom.fem.interface_laws.clamped_iwan import ClampedIwanLaw, clamped_iwan_state
from femrom.fem.interface_laws.dry_friction import DryFrictionLaw
from femrom.fem.interface_laws.iwan import IwanLaw
from femrom.fem.interface_laws.jenkins import JenkinsLaw

__all__ = [
    "DENSITIES", "FORCES", "INTERFACE_LAWS", "ClampedFrictionLaw", "ClampedIwanLaw", "clamped_iwan_state", "clamped_state", "Condensation", "DryFrictionLaw", "ElementMaterial", "ForceSum", "InterfaceLaw",
    "IwanLaw", "JenkinsForce", "JenkinsLaw", "JointForce", "LineSpace", "LocalPotential", "NonlinearForce",
    "ParallelSliderLaw", "QuarticPotential", "SolidSpace", "SpaceError", "TransformedForce", "dense_projection", "transform_force", "force_from_parameters",
    "interface_frames", "interface_law", "interface_law_from_parameters", "radial_return", "slider_return",
    "register_force", "register_interface_law", "relative_displacement_map", "selection_map", "sum_of_forces",
    "average_rows", "axial_stiffness", "CompiledJoint", "CompiledScalar", "CompiledSliders", "compiled_kernels", "compiled_laws", "compiled_scalar_kernels", "use_compiled_laws", "bending_stiffness", "dirichlet_dofs", "elasticity_stiffness",
    "hrz_lumped", "lame_parameters", "line_basis", "line_mass", "nearest_node_rows", "point_load", "probe_rows",
    "rayleigh_damping", "rayleigh_from_damping_ratios", "rigid_body_modes", "surface_pressure",
    "surface_traction", "vector_mass",
]
