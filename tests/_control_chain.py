"""The damped spring-mass chain the control tests drive: inputs at the middle and the last mass."""

import numpy as np
import scipy.sparse as sp

from femrom.scene import SecondOrderSystem


def chain(n=8, m=2, p=3):
    """``n`` unit masses, springs 400, damping ``0.02 K + 0.5 M``; inputs at the middle and the last mass,
    ``p`` displacement outputs spread along it."""
    K = 400.0 * sp.diags([2.0 * np.ones(n), -np.ones(n - 1), -np.ones(n - 1)], [0, 1, -1], format="csr")
    M = sp.identity(n, format="csr")
    B = np.zeros((n, m))
    B[n // 2, 0] = B[-1, 1] = 1.0
    E = np.zeros((p, n))
    E[np.arange(p), np.linspace(1, n - 1, p).astype(int)] = 1.0
    return SecondOrderSystem(mass=M, stiffness=K, damping=0.02 * K + 0.5 * M, input_matrix=B,
                             inputs=lambda t: np.zeros(m), output_matrix=sp.csr_matrix(E))
