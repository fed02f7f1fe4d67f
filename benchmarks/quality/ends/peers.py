import os
import sys

if os.environ.get("PEERS_SITE"):  # pyvista, pymeshlab installed aside
    sys.path.append(os.environ["PEERS_SITE"])
import numpy as np


def vtk_sinc(P, shape, n_iter, pass_band, boundary=True):
    import pyvista as pv

    P3 = P if P.shape[1] == 3 else np.column_stack([P, np.zeros((len(P), 1))])
    if shape.faces is not None:
        pd = pv.PolyData(
            P3, faces=np.column_stack([np.full(len(shape.faces), 3), shape.faces]).ravel()
        )
    else:
        pd = pv.PolyData(
            P3, lines=np.column_stack([np.full(len(shape.edges), 2), shape.edges]).ravel()
        )
    out = pd.smooth_taubin(
        n_iter=n_iter,
        pass_band=pass_band,
        non_manifold_smoothing=True,
        normalize_coordinates=True,
        edge_angle=180.0,
        feature_angle=180.0,
        boundary_smoothing=boundary,
    )
    return np.asarray(out.points, float)[:, : P.shape[1]]


def ml_taubin(P, shape, steps, lam=0.5, mu=-0.53):
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=P, face_matrix=shape.faces.astype(np.int32)))
    ms.apply_coord_taubin_smoothing(lambda_=lam, mu=mu, stepsmoothnum=steps)
    return np.asarray(ms.current_mesh().vertex_matrix(), float)


SINC_GRID = [
    (n, b)
    for n in (10, 20, 40, 80)
    for b in (0.0001, 0.0002, 0.0005, 0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2)
]
TAUBIN_GRID = [
    (s, lam_) for s in (1, 2, 3, 5, 8, 13, 21, 34, 55, 89, 144, 233) for lam_ in (0.33, 0.5, 0.7)
]


def best(scorer, runs):
    bv = bs = (np.inf, None)
    for name, X in runs:
        v, s = scorer.quick(X)
        if v < bv[0]:
            bv = (v, name)
        if s < bs[0]:
            bs = (s, name)
    return bv, bs


def vtk_best(case, scorer, boundary=True):
    return best(
        scorer,
        (
            (f"sinc n{n} pb{b}", vtk_sinc(case.points, case.shape, n, b, boundary))
            for n, b in SINC_GRID
        ),
    )


def taubin_best(case, scorer):
    return best(
        scorer,
        (
            (
                f"taubin {s} l{lam_}",
                ml_taubin(
                    case.points, case.shape, s, lam_, -(lam_ + 0.03 if lam_ < 0.5 else lam_ * 1.06)
                ),
            )
            for s, lam_ in TAUBIN_GRID
        ),
    )
