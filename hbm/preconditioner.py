"""Preconditioners of the reduced Newton systems of the harmonic balance (GMRES path).

The reduced Newton matrix on the k nonlinear elements (p = 3k contact coordinates, n_H = 2H + 1
harmonic rows, layout row h, column 3e + d) is

    J = I + G D,    G_h = R + Psi L_h Psi^T,

with R the static residual flexibility (real, the same at every harmonic), Psi the contact rows
of the kept modes, L_h their modal factors at harmonic h (complex; L_0 real and independent of
the frequency) and D the friction Jacobian, block-diagonal over elements but coupling all
harmonics of an element (3 n_H x 3 n_H per element).

* ``HarmonicAveragedPreconditioner`` (``preconditioner="averaged"``, the default until issue 16's
  session 7): each
  element's D replaced by its mean 3x3 diagonal block over the dynamic harmonics, k_bar, which
  decouples the harmonics; one real LU of I + R k_bar and a rank-m Woodbury correction per
  harmonic.
* ``MeanCoupledPreconditioner`` (``preconditioner="mean-coupled"``): the same on the dynamic harmonics, then the mean
  harmonic solved exactly, J_00 = I + G_0 D_00, with the dynamic harmonics' force D_0h x_h on
  its right-hand side (one block Gauss-Seidel sweep): one real LU and the static receptance
  G_0 on the elements more than the averaged one.
* ``ElementBlockPreconditioner`` (``preconditioner="element"``, the default from session 7 to
  27): block Jacobi over the
  elements, each element's own block of J inverted exactly, I + G_ee D_e (3 n_H x 3 n_H, every
  harmonic coupled, the mean's included); the elastic coupling between elements is dropped. Its
  set-up is k small inverses, rebuilt at every solve.
* ``PatchPreconditioner`` (``preconditioner="patches"``, the default since session 28): the
  element blocks, then a coarse correction on patches of about 15 elements (``PatchSpace``,
  ``interface_patches``), which restores the smooth part of the elastic coupling between
  elements. On 28 Newton systems captured from the default model's top-level baseline sweep
  (k = 73-353): 322 GMRES iterations in all against 1192 for the element blocks, 0.85 against
  1.25 s (set-up 13 ms against 6 ms at k = 353); the whole curve 41 -> 17.1 iterations per
  solve (the coarse factor reused, ``HarmonicBalance``), 37.4 -> 30.0 s.
* ``TwoLevelPreconditioner`` (``preconditioner="two-level"``): the averaged one, then the
  element blocks on the residual it leaves (multiplicative; one more product with J).

Whole curves of the default model (``scripts/bench_preconditioner.py``, one process per
preconditioner, two at a time on the two cores), time (GMRES iterations per solve): baseline at
the top level, element 222.7 s (81.3), two-level 299.4 s (56.2), averaged 386 s (92.0); v2 at
the top level 71.7 (40.9) / 97.0 (27.9); v2 at the middle level 30.9 (22.3) / 38.4 (15.5);
smooth-ms at the middle level 26.8 (36.4) / 36.6 (24.2); the same points and peaks (to the
digits of the table). The element blocks' application is a batch of small products and they
are never stale; the two-level one saves iterations but pays a product with J and an averaged
application in each. On the stiff layer joint's backbone the element blocks took 146-286 s
where the averaged one had taken 516 s (and stopped at a kink, see ``nonlinear_mode``).

Session 7 (issue 16), on Newton systems captured from the default model (H = 3, p = 645-1059),
GMRES iterations per solve, averaged / mean-coupled / element / two-level: the top-level
baseline sweep 50-112 / 41-73 / 51-107 / 29-66; the stiff layer joint's backbone (k_n 10 x the
patch value, 231-289 elements) 287-426 / 226-258 / 107-148 / 70-111. In the friction Jacobian
minus its harmonic average, D - k_bar, every element counts (relative norm 1.3-1.7, median):
no small set of elements carries the harmonic coupling, so a low-rank correction of the
averaged preconditioner is not an option. A stale exact LU of J (7413 unknowns, 4.9 s; float32
3.1 s) needed 19, 49 and 95 iterations 12, 24 and 36 solves after it was built, at the same
nonlinear set: the friction Jacobian moves too fast for a factorization to be reused.

How the first two were chosen (31 Newton systems of the quick model's top-level baseline sweep, 201
nonlinear elements, p = 603, H = 1, GMRES to 1e-8; ``scripts/bench_preconditioner.py`` for whole
curves):

* The averaged preconditioner needs 63-88 iterations per solve there. Replacing parts of D by
  their harmonic average *in the system* located what it misses: with the mean (h = 0) row and
  column averaged it needs 20, with the tangential blocks averaged 25, the t-n coupling 66, the
  normal-normal block 65. The coupling of the mean displacement to the vibration (the static
  shear in a slipping joint follows the slip phases) is what matters most.
* Tried and dropped: a collocation of D at 2H + 1 instants (one LU per instant, exact for a
  time-local D): 75. The mean block exact plus, per dynamic harmonic, the elements' complex
  stiffness (D_cc + D_ss)/2 + i (D_cs - D_sc)/2 (the part of a harmonic's cosine/sine block that
  commutes with complex multiplication, friction's hysteresis included): 24-30 iterations, but
  a complex LU solve (zgetrs, one right-hand side) took 1.5 ms against 0.4 ms for the product
  with the explicit inverse, and the explicit complex inverse costs 180 ms at p = 603 and 840 ms
  at p = 1020 per harmonic: with H = 3 on the default model its set-up outweighed the 10-20 %
  fewer iterations than the mean-coupled one.
* Built: the mean-coupled one, 22-37 iterations (p = 483-603), each application 1.5-1.8 times
  the averaged one's (an LU solve and a product with G_0 more), a set-up about twice (39 against
  20 ms at p = 603).
* Reuse (``harmonic_balance._PreconditionerCache``) did more than either: on the same sweep a
  preconditioner built 17 solves earlier needed the same number of iterations as a fresh one,
  so it is kept while the nonlinear set is unchanged (535 set-ups became 71 on that curve).
* Not the default: with the mean-coupled preconditioner, the quick preset's top-level baseline
  sweep on a reduced model rebuilt by a second FE run (1e-8 apart) had not finished after 17
  minutes (70 s on the first model; 94 s with the averaged one on the second). Not understood
  yet; until it is, the averaged preconditioner (with the reuse) is the default and the
  mean-coupled one an option, measured by ``scripts/bench_preconditioner.py``.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as sla


def _times_blockdiag(X: np.ndarray, K: np.ndarray) -> np.ndarray:
    """X @ blockdiag(K) for X (p, p) and K (k, 3, 3), p = 3k, without forming blockdiag(K)."""
    p, k = X.shape[0], K.shape[0]
    Y = np.matmul(X.reshape(p, k, 3).transpose(1, 0, 2), K)          # (k, p, 3)
    return Y.transpose(1, 0, 2).reshape(p, p)


class HarmonicAveragedPreconditioner:
    """The default preconditioner (``preconditioner="averaged"``):
    each element's D replaced by its mean 3x3 diagonal block over the dynamic harmonics, k_bar,
    so that the harmonics decouple; the exact inverse of I + G_h k_bar is one real LU of
    I + R k_bar and a rank-m Woodbury correction per harmonic.

    Args: as :class:`HarmonicBlockPreconditioner`.
    """

    def __init__(self, R: np.ndarray, Psi: np.ndarray, Ls: list, Dg: np.ndarray) -> None:
        k = Dg.shape[0]
        H = len(Ls) - 1
        nH, p = 2 * H + 1, 3 * k
        self.nH, self.p = nH, p
        Dh = Dg.reshape(k, 3, nH, 3, nH)
        hh = np.arange(1, nH)
        kbar = Dh[:, :, hh, :, hh].mean(axis=0)                        # (k, 3, 3)
        A = _times_blockdiag(R, kbar)
        A[np.diag_indices(p)] += 1.0
        self.lu = sla.lu_factor(A, check_finite=False)
        self.AinvU = sla.lu_solve(self.lu, Psi, check_finite=False)    # (p, m)
        self.VtK = np.einsum("kam,kab->mkb", Psi.reshape(k, 3, -1), kbar).reshape(-1, p)
        VtAU = self.VtK @ self.AinvU
        self.facs = []
        for L in Ls:
            Lm = np.diag(L) if L.ndim == 1 else L
            self.facs.append((sla.lu_factor(np.eye(Lm.shape[0]) + Lm @ VtAU, check_finite=False), Lm))

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Approximate J^-1 x for x (n_H p,) in the reduced layout."""
        nH, p = self.nH, self.p
        y = sla.lu_solve(self.lu, x.reshape(nH, p).T, check_finite=False)   # (p, nH)
        W = self.VtK @ y
        S = np.empty_like(W)
        for h, (f, Lm) in enumerate(self.facs):
            wh = W[:, 0] if h == 0 else W[:, 2 * h - 1] - 1j * W[:, 2 * h]
            sh = sla.lu_solve(f, Lm @ wh, check_finite=False)
            if h == 0:
                S[:, 0] = sh.real
            else:
                S[:, 2 * h - 1], S[:, 2 * h] = sh.real, -sh.imag
        return (y - self.AinvU @ S).T.ravel()


class MeanCoupledPreconditioner:
    """Approximate inverse of J = I + G D on the nonlinear elements (module docstring): the
    harmonic-averaged preconditioner on the dynamic harmonics, then the mean harmonic solved
    exactly with their force D_0h x_h moved to its right-hand side (one Gauss-Seidel sweep).

    Args:
        R: (p, p) static residual flexibility on the elements' contact coordinates, mm/N.
        Psi: (p, m) contact rows of the kept modes.
        Ls: modal factors L_h for h = 0..H, each (m,) or (m, m), complex.
        Dg: (k, 3 n_H, 3 n_H) element Jacobians of the correction force, element layout
            d n_H + h, N/mm.
    """

    def __init__(self, R: np.ndarray, Psi: np.ndarray, Ls: list, Dg: np.ndarray) -> None:
        k = Dg.shape[0]
        H = len(Ls) - 1
        nH, p = 2 * H + 1, 3 * k
        self.nH, self.p, self.k = nH, p, k
        self.dynamic = HarmonicAveragedPreconditioner(R, Psi, Ls, Dg)
        D5 = Dg.reshape(k, 3, nH, 3, nH)
        L0 = Ls[0].real
        G0 = R + ((Psi * L0) if L0.ndim == 1 else Psi @ L0) @ Psi.T
        J00 = _times_blockdiag(G0, np.ascontiguousarray(D5[:, :, 0, :, 0]))
        J00[np.diag_indices(p)] += 1.0
        # x_0 = J_00^-1 (r_0 - G_0 f_0): an LU (an explicit [J_00^-1, -J_00^-1 G_0] cost 5 times
        # its set-up, which the default model's middle-level curves, one set-up per point, felt)
        self.G0, self.lu0 = G0, sla.lu_factor(J00, check_finite=False)
        # force at the mean row from the dynamic displacements: D_0h, (nH - 1, k, 3, 3)
        self.D0d = np.ascontiguousarray(D5[:, :, 0, :, 1:].transpose(3, 0, 1, 2))

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Approximate J^-1 x for x (n_H p,) in the reduced layout (row h, column 3e + d)."""
        nH, p, k = self.nH, self.p, self.k
        out = self.dynamic(x).reshape(nH, p)
        f0 = np.einsum("hkab,hkb->ka", self.D0d, out[1:].reshape(nH - 1, k, 3)).ravel()
        out[0] = sla.lu_solve(self.lu0, x[:p] - self.G0 @ f0, check_finite=False)
        return out.ravel()


class ElementBlockPreconditioner:
    """The exact inverse of each element's own block of J (block Jacobi over elements): the
    element's receptance on itself at every harmonic, G_ee,h = R_ee + Psi_e L_h Psi_e^T, times its
    whole friction Jacobian D_e, all harmonics coupled: (I + G_ee D_e)^-1, 3 n_H x 3 n_H each.

    It keeps what the averaged preconditioner drops (the coupling between harmonics, the mean's
    included) and drops what it keeps (the elastic coupling between elements). Its set-up is k
    small inverses, so it is rebuilt at every solve (``fresh``), never stale.

    Args: as :class:`MeanCoupledPreconditioner`.
    """

    fresh = True

    def __init__(self, R: np.ndarray, Psi: np.ndarray, Ls: list, Dg: np.ndarray) -> None:
        k = Dg.shape[0]
        H = len(Ls) - 1
        nH, p = 2 * H + 1, 3 * k
        self.nH, self.p, self.k = nH, p, k
        e = np.arange(k)
        Ree = R.reshape(k, 3, k, 3)[e, :, e, :]                            # (k, 3, 3)
        Pe = Psi.reshape(k, 3, -1)                                         # (k, 3, m)
        G = np.zeros((k, 3, nH, 3, nH))                                    # element layout
        for h, Gh in enumerate(_own_receptances(Ree, Pe, Ls)):
            if h == 0:
                G[:, :, 0, :, 0] = Gh.real
            else:
                a, b = 2 * h - 1, 2 * h
                G[:, :, a, :, a], G[:, :, a, :, b] = Gh.real, Gh.imag
                G[:, :, b, :, a], G[:, :, b, :, b] = -Gh.imag, Gh.real
        GD = G.reshape(k, 3 * nH, 3 * nH) @ Dg
        scale = 1.0 + np.abs(GD).sum(axis=1).max(axis=1)          # ||I|| + ||G_ee D_e||, 1-norm
        GD[:, np.arange(3 * nH), np.arange(3 * nH)] += 1.0
        self.inv = _block_inverses(GD, scale)
        # reduced-layout index (h p + 3e + d) of element-layout entry (e, d n_H + h)
        d, hh = np.divmod(np.arange(3 * nH), nH)
        self.idx = hh[None, :] * p + 3 * e[:, None] + d[None, :]

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Approximate J^-1 x for x (n_H p,) in the reduced layout."""
        out = np.empty_like(x)
        out[self.idx] = np.matmul(self.inv, x[self.idx][:, :, None])[:, :, 0]
        return out


def _own_receptances(Ree: np.ndarray, Pe: np.ndarray, Ls: list) -> list:
    """Each element's receptance on itself at every harmonic, G_ee,h = R_ee + Psi_e L_h Psi_e^T.

    Args:
        Ree: (k, 3, 3) the elements' own blocks of R.
        Pe: (k, 3, m) their rows of the kept modes.
        Ls: modal factors per harmonic, (m,) or (m, m).
    Returns:
        H + 1 arrays (k, 3, 3), the first real.
    """
    if all(np.ndim(L) == 1 for L in Ls):
        # every harmonic's real and imaginary factors in one batched product (four einsums
        # took 3 of the element blocks' 7 ms set-up at 353 elements)
        F = np.stack([Ls[0].real] + [f for L in Ls[1:] for f in (L.real, L.imag)])  # (2H+1, m)
        M = np.matmul(Pe[:, None] * F[None, :, None, :], Pe.transpose(0, 2, 1)[:, None])
        return [Ree + M[:, 0]] + [(Ree + M[:, 2 * h - 1]) + 1j * M[:, 2 * h]
                                  for h in range(1, len(Ls))]
    return [Ree + np.einsum("kam,mn,kbn->kab", Pe, L if L.ndim == 2 else np.diag(L), Pe)
            for L in Ls]


#: ||A^-1|| (||I|| + ||G D||) (1-norms) above which an element's block A = I + G D counts as
#: singular (its inverse would only amplify round-off: about 1 / (500 eps))
MAX_BLOCK_CONDITION = 1e13


def _block_inverses(A: np.ndarray, scale: np.ndarray | None = None) -> np.ndarray:
    """Inverses of the blocks A (k, n, n); a singular block's is the identity.

    Args:
        A: the blocks.
        scale: (k,) the 1-norm of the terms each block is the sum of (I + G D: 1 + ||G D||);
            None: the block's own norm.

    An element's own block can be singular although J is not (the elastic coupling to the other
    elements makes up for it): the stiff layer joint's backbone on a quick-preset model met one
    (session 14), and numpy's batched inverse then raised through the whole study. Such an
    element is left unpreconditioned; GMRES sees the rest preconditioned as before.

    Singular in floating point, not only exactly: a block I + G D that cancels to round-off
    (entries of 1e-16) is inverted without a zero pivot to entries of 1e17 (on an AMD EPYC whose
    OpenBLAS rounds differently; elsewhere LAPACK met an exact zero). So a block counts as
    singular too when ||A^-1|| times the norm of its terms exceeds :data:`MAX_BLOCK_CONDITION`.
    """
    try:
        out = np.linalg.inv(A)
    except np.linalg.LinAlgError:
        out = np.empty_like(A)
        for e in range(A.shape[0]):           # the rare failure path only
            try:
                out[e] = np.linalg.inv(A[e])
            except np.linalg.LinAlgError:
                out[e] = np.inf
    if scale is None:
        scale = np.abs(A).sum(axis=1).max(axis=1)
    with np.errstate(invalid="ignore", over="ignore"):
        cond = scale * np.abs(out).sum(axis=1).max(axis=1)
    out[~(cond <= MAX_BLOCK_CONDITION)] = np.eye(A.shape[1])
    return out


class TwoLevelPreconditioner:
    """The averaged preconditioner (elastic coupling between elements, harmonics averaged), then
    the element blocks on what is left (harmonic coupling within each element), multiplicatively:
    z = A r, z += E (r - J z). One more product with J per application.

    Measured on Newton systems captured from the default model (H = 3), GMRES iterations per
    solve (averaged / element blocks alone / this): the top-level baseline sweep (215-353
    nonlinear elements) 50-112 / 51-107 / 29-66; the stiff layer joint's backbone (k_n 10 x,
    231-289 elements) 287-426 / 107-148 / 70-111.

    Args:
        averaged: a :class:`HarmonicAveragedPreconditioner` (may be reused from earlier solves).
        element: an :class:`ElementBlockPreconditioner` of this solve's Jacobian.
        matvec: x -> J x in the reduced layout.
    """

    def __init__(self, averaged, element, matvec) -> None:
        self.averaged, self.element, self.matvec = averaged, element, matvec

    def __call__(self, x: np.ndarray) -> np.ndarray:
        z = self.averaged(x)
        return z + self.element(x - self.matvec(z))


#: elements per patch of the two-level preconditioner's coarse space (``PatchPreconditioner``):
#: on Newton systems captured from the default model's top-level baseline sweep, patches of 12 /
#: 15 / 20 elements took 211 / 239 / 268 GMRES iterations where the element blocks took 1192
#: (28 systems); the coarse LU grows as (21 k / PATCH_ELEMENTS)^3: on whole top-level curves
#: 10 or 12 elements per patch saved 5-10 % of the iterations and took longer
PATCH_ELEMENTS = 15
#: medoid refinements of the patches (``interface_patches``): one or three gave 239 / 240
#: iterations on those systems against 282 with the farthest-point seeds alone
PATCH_ROUNDS = 2


def element_coupling(R: np.ndarray) -> np.ndarray:
    """Normalized elastic coupling of the elements through R: |tr R_ij| / sqrt(tr R_ii tr R_jj).

    Args:
        R: (3k, 3k) static residual flexibility on the elements' contact coordinates, mm/N.
    Returns:
        (k, k), 1 on the diagonal.
    """
    k = R.shape[0] // 3
    t = np.einsum("iaja->ij", R.reshape(k, 3, k, 3))
    s = np.sqrt(np.abs(np.diag(t)))
    s[s == 0] = 1.0
    return np.abs(t) / np.outer(s, s)


def interface_patches(R: np.ndarray, n: int, rounds: int = PATCH_ROUNDS) -> np.ndarray:
    """Groups the elements into about n patches of strongly coupled neighbours, from R alone
    (no coordinates: a joint's elements couple through the elastic body as their distance does).

    Seeds by farthest-point sampling in the coupling (the next seed is the element least coupled
    to every seed so far), each element joining the seed it is most coupled to, then ``rounds``
    times each patch's seed moved to its medoid (the element most coupled to its patch).

    Args:
        R: (3k, 3k) static residual flexibility on the elements' coordinates.
        n: number of patches wanted (clipped to [1, k]).
    Returns:
        (k,) patch labels 0..n'-1, every patch non-empty.
    """
    C = element_coupling(R)
    k = C.shape[0]
    n = max(1, min(int(n), k))
    seeds = [int(np.argmin(C.sum(axis=1)))]
    near = C[seeds[0]].copy()
    for _ in range(n - 1):
        j = int(np.argmin(near))
        seeds.append(j)
        np.maximum(near, C[j], out=near)
    seeds = np.array(seeds)
    for _ in range(rounds):
        lab = np.argmax(C[seeds], axis=0)
        member = lab[None, :] == np.arange(n)[:, None]                      # (n, k)
        inside = np.where(member, member.astype(float) @ C, -np.inf)
        seeds = np.argmax(inside, axis=1)
    _, lab = np.unique(np.argmax(C[seeds], axis=0), return_inverse=True)
    return lab


def _modal_mix(Ls: list, W: np.ndarray) -> np.ndarray:
    """The modal factors of each harmonic applied to modal rows W (m, n_H, ...): row 0 the mean,
    rows 2h-1, 2h the cosine and sine of harmonic h (complex amplitude x - i y), as the
    receptance's modal part does; Ls[h] (m,) diagonal or (m, m)."""
    S = np.empty_like(W)
    for h, L in enumerate(Ls):
        if h == 0:
            L0 = L.real
            S[:, 0] = (L0.reshape((-1,) + (1,) * (W.ndim - 2)) * W[:, 0] if L0.ndim == 1
                       else np.tensordot(L0, W[:, 0], axes=1))
            continue
        z = W[:, 2 * h - 1] - 1j * W[:, 2 * h]
        z = (L.reshape((-1,) + (1,) * (W.ndim - 2)) * z if L.ndim == 1
             else np.tensordot(L, z, axes=1))
        S[:, 2 * h - 1], S[:, 2 * h] = z.real, -z.imag
    return S


class PatchSpace:
    """The coarse space of ``PatchPreconditioner`` for one nonlinear set: per patch of elements
    (``interface_patches``), direction and harmonic row, the patch's uniform motion (normalized),
    Z (n_H p, 21 n_patches); and Z^T R, Z^T Psi, which carry the coarse rows of J's product.

    Args:
        R: (p, p) static residual flexibility on the elements' contact coordinates, mm/N.
        Psi: (p, m) contact rows of the kept modes.
        nH: harmonic rows 2H + 1.
        per_patch: elements per patch (None: :data:`PATCH_ELEMENTS`).
    """

    def __init__(self, R: np.ndarray, Psi: np.ndarray, nH: int,
                 per_patch: int | None = None) -> None:
        p, m = Psi.shape
        k = p // 3
        lab = interface_patches(R, max(1, round(k / (per_patch or PATCH_ELEMENTS))))
        nc = int(lab.max()) + 1
        order = np.argsort(lab, kind="stable")
        starts = np.searchsorted(lab[order], np.arange(nc))
        size = np.diff(np.append(starts, k))
        w = 1.0 / np.sqrt(size)[lab]                                    # (k,) Z's entries
        self.k, self.nH, self.nc, self.m = k, nH, nc, m
        self.lab, self.order, self.starts, self.size, self.w = lab, order, starts, size, w
        ws = w[order, None, None]
        # the coarse rows (patch, direction) of R and Psi, and their columns sorted by patch
        ZR = np.add.reduceat(R.reshape(k, 3, p)[order] * ws, starts, axis=0).reshape(3 * nc, p)
        self.ZR = ZR                                                    # (3 nc, p)
        self.ZR_sorted = np.ascontiguousarray(ZR.reshape(3 * nc, k, 3)[:, order].reshape(3 * nc, p))
        Pe = Psi.reshape(k, 3, m)
        self.ZPsi = np.add.reduceat(Pe[order] * ws, starts, axis=0).reshape(3 * nc, m)
        self.PsiT_sorted = np.ascontiguousarray(Pe[order].transpose(2, 0, 1).reshape(m, p))

    def restrict(self, r: np.ndarray) -> np.ndarray:
        """Z^T r for r (n_H p,) in the reduced layout: (nc n_H 3,), order (patch, row, direction)."""
        x = r.reshape(self.nH, self.k, 3)[:, self.order] * self.w[self.order, None]
        return np.add.reduceat(x, self.starts, axis=1).transpose(1, 0, 2).ravel()

    def prolong(self, c: np.ndarray) -> np.ndarray:
        """Z c for coarse c (nc n_H 3,): (n_H p,) in the reduced layout."""
        c = c.reshape(self.nc, self.nH, 3)
        return (c[self.lab].transpose(1, 0, 2) * self.w[None, :, None]).ravel()


def coarse_matrix(space: PatchSpace, Psi: np.ndarray, Ls: list, Dg: np.ndarray) -> np.ndarray:
    """Z^T J Z on the patches' coarse space, assembled patch by patch from the friction blocks and
    the coarse rows Z^T R, Z^T Psi (no product with J).

    Args: as :class:`ElementBlockPreconditioner`, and
        space: the nonlinear set's :class:`PatchSpace`.
    Returns:
        (21 nc, 21 nc) on H = 3 (3 n_H per patch), rows and columns in the coarse order (patch,
        harmonic row, direction).
    """
    sp_, k, nH, nc, m = space, space.k, space.nH, space.nc, space.m
    # Z^T G D Z, column (patch c, row h, direction d): D Z is w_e D_e[:, d n_H + h] on c
    D = (Dg * sp_.w[:, None, None])[sp_.order].reshape(3 * k, nH * 3 * nH)         # sorted
    A = np.empty((nc, 3 * nc, nH * 3 * nH))
    U = np.empty((nc, m, nH * 3 * nH))
    for c in range(nc):
        s = slice(3 * sp_.starts[c], 3 * (sp_.starts[c] + sp_.size[c]))
        A[c] = sp_.ZR_sorted[:, s] @ D[s]
        U[c] = sp_.PsiT_sorted[:, s] @ D[s]
    U = U.reshape(nc, m, nH, 3 * nH).transpose(1, 2, 0, 3)                     # (m, h', c, b)
    A += (sp_.ZPsi @ _modal_mix(Ls, U).reshape(m, -1)).reshape(3 * nc, nH, nc, 3 * nH) \
        .transpose(2, 0, 1, 3).reshape(nc, 3 * nc, nH * 3 * nH)
    # rows (c', d', h'), columns (c, d, h) -> both in the coarse order (patch, row, direction)
    Ac = A.reshape(nc, nc, 3, nH, 3, nH).transpose(1, 3, 2, 0, 5, 4).reshape(3 * nH * nc, -1)
    Ac[np.diag_indices_from(Ac)] += 1.0                                         # Z^T Z = I
    return Ac


class CoarseFactor:
    """The LU of Z^T J Z (``coarse_matrix``), or None where it is singular (J may be nearly
    singular at a fold): the element blocks then work alone. It may serve later solves of the
    same nonlinear set (``HarmonicBalance``'s preconditioner cache): the coarse correction stays a
    fixed linear map, only a less exact one, while the element blocks are always fresh.

    Args: as :func:`coarse_matrix`.
    """

    def __init__(self, space: PatchSpace, Psi: np.ndarray, Ls: list, Dg: np.ndarray) -> None:
        lu, piv = sla.lu_factor(coarse_matrix(space, Psi, Ls, Dg), check_finite=False)
        pivots = np.abs(np.diag(lu))
        ok = np.all(np.isfinite(lu)) and pivots.min() > 1e-13 * pivots.max()
        self.lu = (lu, piv) if ok else None

    def solve(self, c: np.ndarray) -> np.ndarray:
        """(Z^T J Z)^-1 c for coarse c."""
        return sla.lu_solve(self.lu, c, check_finite=False)


class PatchPreconditioner:
    """Two-level (``preconditioner="patches"``): the element blocks (``ElementBlockPreconditioner``)
    and a coarse correction on patches of elements (``PatchSpace``): z = E r, then
    z + Z (Z^T J Z)^-1 Z^T (r - J z) (the "deflation" order A-DEF2, Tang et al. 2009).

    What the element blocks leave is the elastic coupling between elements in J = I + G D: D is
    the friction Jacobian minus the stuck springs, so where elements slip or open the block's own
    share (R_ee D_e about -0.3 on the top-level curves) is a third of the coupling through the
    neighbours' R (normalized row sums about 3): GMRES then needs 40-100 iterations, and the
    slow part is smooth over the interface. One uniform motion per patch, direction and harmonic
    row catches it; one over the whole interface did not (session 24).

    Z^T J z needs only the coarse rows of G (Z^T R, Z^T Psi: 3 nc x p), so an application costs
    the element blocks, one block product with D, a (3 nc, p) x (p, n_H) product and the coarse
    solve, not a second product with J.

    Args: as :class:`ElementBlockPreconditioner`, and
        space: the nonlinear set's :class:`PatchSpace`.
        coarse: the :class:`CoarseFactor` to use (an earlier solve's may be reused); None:
            this system's own.
    """

    fresh = True

    def __init__(self, space: PatchSpace, R: np.ndarray, Psi: np.ndarray, Ls: list,
                 Dg: np.ndarray, coarse: CoarseFactor | None = None) -> None:
        self.element = ElementBlockPreconditioner(R, Psi, Ls, Dg)
        self.coarse = CoarseFactor(space, Psi, Ls, Dg) if coarse is None else coarse
        self.space, self.Dg, self.Ls, self.Psi = space, Dg, Ls, Psi
        self.idx = self.element.idx           # reduced-layout index of the element layout

    def coarse_rows(self, z: np.ndarray) -> np.ndarray:
        """Z^T J z for z (n_H p,) in the reduced layout, from the coarse rows of R and Psi."""
        sp_, nH = self.space, self.space.nH
        g = np.empty_like(z)
        g[self.idx] = np.matmul(self.Dg, z[self.idx][:, :, None])[:, :, 0]
        g = g.reshape(nH, -1).T                                                 # (p, n_H)
        out = sp_.ZR @ g + sp_.ZPsi @ _modal_mix(self.Ls, self.Psi.T @ g)       # (3 nc, n_H)
        return sp_.restrict(z) + out.reshape(sp_.nc, 3, nH).transpose(0, 2, 1).ravel()

    def __call__(self, r: np.ndarray) -> np.ndarray:
        """Approximate J^-1 r for r (n_H p,) in the reduced layout."""
        z = self.element(r)
        if self.coarse.lu is None:
            return z
        c = self.coarse.solve(self.space.restrict(r) - self.coarse_rows(z))
        return z + self.space.prolong(c)


#: the preconditioners ``HarmonicBalance(preconditioner=...)`` accepts ("two-level" is built by
#: the solver from the averaged one and the element blocks, as it needs the Jacobian's product)
PRECONDITIONERS = {"averaged": HarmonicAveragedPreconditioner,
                   "mean-coupled": MeanCoupledPreconditioner,
                   "element": ElementBlockPreconditioner,
                   "two-level": HarmonicAveragedPreconditioner,
                   "patches": PatchPreconditioner}
