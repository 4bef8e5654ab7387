"""Movement primitives of thesis Sec. 2.6.1: ProMP (Eq. 2.46), DMP (Eq. 2.45) and ProDMP.

All three map a low-dimensional parameter vector to a trajectory of shape ``(..., T, n_dof)``,
batched over the leading dimensions of the parameters; inputs may be numpy arrays or tensors,
outputs are torch tensors (float64 by default). ProMP and ProDMP also evaluate numpy arrays
without torch (``trajectory_numpy``), which is what the robot tasks use.
"""

from vslbook.movement.dmp import DMP
from vslbook.movement.prodmp import ProDMP
from vslbook.movement.promp import ProMP

__all__ = ["DMP", "ProDMP", "ProMP"]
