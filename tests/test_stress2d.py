"""2D stresses written to ParaView (BodiesWriter): values, not only shapes. Blocks rotated by several angles carry
a uniform strain (an affine displacement field in their type frame, reproduced exactly by P1 and Q1 elements);
the expected global stress is Hooke's law in the type frame rotated by R σ Rᵀ, and von Mises is the plane-stress
(or plane-strain, σzz = ν(σxx + σyy)) formula, all computed here."""
import numpy as np
import pytest

from fem_blocks.bodies import BlockType, DeformableBody, Material
from fem_blocks.dynamics import Simulation
from fem_blocks.meshing import mesh_rectangle
from fem_blocks.output.paraview import BodiesWriter

E, NU = 2e10, 0.25
GRAD = np.array([[1.0e-4, 3.0e-4], [-0.5e-4, -2.0e-4]])  # displacement gradient du/dX in the type frame
ANGLES = (0.0, 0.3, 2.0, -1.1)


def hooke(plane):
    """Type-frame stress (σxx, σyy, σxy) of the strain sym(GRAD): plane stress E/(1-ν²) [[1, ν], [ν, 1]],
    plane strain E/((1+ν)(1-2ν)) [[1-ν, ν], [ν, 1-ν]], shear G γxy with G = E/(2(1+ν))."""
    exx, eyy, gxy = GRAD[0, 0], GRAD[1, 1], GRAD[0, 1] + GRAD[1, 0]
    if plane == "stress":
        sxx, syy = E / (1 - NU ** 2) * (exx + NU * eyy), E / (1 - NU ** 2) * (eyy + NU * exx)
    else:
        f = E / ((1 + NU) * (1 - 2 * NU))
        sxx, syy = f * ((1 - NU) * exx + NU * eyy), f * ((1 - NU) * eyy + NU * exx)
    return np.array([[sxx, E / (2 * (1 + NU)) * gxy], [E / (2 * (1 + NU)) * gxy, syy]])


@pytest.mark.parametrize("plane", ["stress", "strain"])
@pytest.mark.parametrize("cell", ["quad", "triangle"])
def test_rotated_blocks_stress_and_von_mises(tmp_path, plane, cell):
    bt = BlockType(mesh_rectangle(0.4, 0.2, 0.1, cell=cell),
                   Material(E=E, nu=NU, rho=2000.0, thickness=0.1, plane=plane), name="b")
    bodies = [DeformableBody(bt, position=(i * 1.0, 0.0), angle=a, name=f"b{i}") for i, a in enumerate(ANGLES)]
    sim = Simulation(bodies, h=1e-3, theta=0.5, gravity=(0.0, 0.0))
    X = bt.mesh.points
    for b in bodies:
        b.q[:] = (X @ GRAD.T).ravel()  # type frame, interleaved dofs
    point_data, cell_data = BodiesWriter(sim, str(tmp_path)).fields()
    sig, vm, body_id = cell_data["stress"], cell_data["von_mises"], cell_data["body_id"]
    s_type = hooke(plane)
    nc = bt.mesh.cells.shape[0]
    for i, a in enumerate(ANGLES):
        c, s = np.cos(a), np.sin(a)
        R = np.array([[c, -s], [s, c]])
        sg = R @ s_type @ R.T
        sxx, syy, sxy = sg[0, 0], sg[1, 1], sg[0, 1]
        if plane == "stress":
            vm_ref = np.sqrt(sxx ** 2 - sxx * syy + syy ** 2 + 3 * sxy ** 2)
        else:
            szz = NU * (sxx + syy)
            vm_ref = np.sqrt(0.5 * ((sxx - syy) ** 2 + (syy - szz) ** 2 + (szz - sxx) ** 2) + 3 * sxy ** 2)
        rows = body_id == i
        assert rows.sum() == nc
        scale = np.abs(s_type).max()
        np.testing.assert_allclose(sig[rows], np.tile([sxx, syy, sxy], (nc, 1)), rtol=0, atol=1e-9 * scale)
        np.testing.assert_allclose(vm[rows], vm_ref, rtol=1e-9)
        # displacement written in the global frame: R (GRAD X)
        n = X.shape[0]
        np.testing.assert_allclose(point_data["displacement"][i * n:(i + 1) * n], (X @ GRAD.T) @ R.T,
                                   rtol=0, atol=1e-15)
    # the shear term matters in von Mises here: 3σxy² is at least 5 % of σ_vm² in every cell
    assert np.all(3 * sig[:, 2] ** 2 >= 0.05 * vm ** 2)
