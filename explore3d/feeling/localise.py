"""Contact localisation from proprioception: where on which link the chain touches, from the
joint angles and the external joint torques at one quasi-static moment (pure numpy).  The
pipeline calls it through :mod:`explore3d.feeling.contacts` on each detection's settled reading.

Model.  All joint axes are the base z axis, contact is frictionless, so a contact on link i at
point p (world) with force F (along the contact normal, pushing the link away from the object)
gives the external joint torques ``tau_j = z . ((p - o_j) x F)`` for j <= i and 0 beyond.  At a
quasi-static moment the motors balance them: ``tau_ext = -(tau_motor + g(q))`` (g: the links'
weights, :func:`explore3d.arm.kinematics.gravity_torques`).  Joint torques see only the in-plane force
and the moment about z: the height of a contact across the link (z in [-H/2, H/2]) is
unobservable and reported as an interval (the point itself is given at mid-height, z = 0).

Candidates.  Each link's in-plane outline is the L x W rectangle (link frame: x in [0, L],
y in [-W/2, W/2]).  One contact on link i is either

* on a *face* (one of the four edges of the rectangle) with the force along that face's inward
  normal (into the link), or
* at a *corner*, with the force anywhere in the cone spanned by the two adjacent faces' normals.

Both are a nonnegative combination of two *generators* (a unit force along a face normal at a
corner of that face): a face contact of force f at arc position s in [0, len] is statically the
pair f (1 - s/len) and f s/len at the face's two corners (so s = len * f_b / (f_a + f_b)); a corner
contact is its two face normals at one corner.  For any set of (link, kind) candidates the joint
torques are linear in the generator weights, and the fit is a nonnegative least squares problem.

A *flat* (distributed) contact -- a link face lying along a face of the object -- is represented
exactly by its centre of pressure: the resultant of a distributed normal load on one face is a
single force along that normal at a point of the face, which is what a face candidate reports.

Search.  At most one contact per link.  Greedy forward selection: start from no contact; in each
round try every (link, kind) candidate on a not-yet-used link at or proximal to one past the most
distal joint with a significant torque, refit every chosen contact jointly (NNLS), keep the
candidate that lowers the residual sum of squares the most, and stop when the drop is below
``chi2_gain * sigma^2`` (a significance threshold from the torque noise ``sigma``).  Then each chosen
contact is re-chosen with the others fixed (a few swap passes), and contacts whose removal costs
less than the threshold are dropped.  Each round first bounds every candidate's residual from below
by the unconstrained least squares one (a few vectorised projections) and fits only those whose
bound could beat the round's best: the same choice as fitting them all, in a fraction of the fits
(measured on the default cube, one run: 2.23 million fits before, 0.31 million after).

Uncertainty.  From the fit's covariance ``sigma^2 (A^T A)^-1`` on the active generators, propagated
to the arc position along the face (about ``sigma / |F|`` in scale: what a reading resolves).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import nnls

from explore3d.arm.kinematics import gravity_torques, link_transforms
from explore3d.arm.spec import ArmSpec

__all__ = ["LocalContact", "Localisation", "localise", "external_torques", "link_outline", "KINDS", "INNER_SIDE", "INNER_SIDE_ROUNDED", "TIP_EXTRA", "CHI2_GAIN", "inverse_dynamics",
           "torques_of_contacts"]

#: The default significance gain: a contact is kept when it lowers the residual sum of squares by at
#: least this many torque variances (:func:`localise`).
CHI2_GAIN = 25.0

#: Candidate kinds on a link's in-plane outline: four faces, four corners.
KINDS = ("inner", "outer", "distal", "proximal", "corner_di", "corner_do", "corner_pi", "corner_po")

#: The kinds an object on the curl side can touch (default): the inner face and its two corners,
#: and the tip link's distal face and corners.  A link's end faces lie against its neighbours' (the
#: gaps between links open on the outer side as the chain curls), the outer face looks away from
#: the object; candidates there only fit noise (a force along a straight distal chain has almost
#: no lever and fits anything with a huge magnitude).
INNER_SIDE = ("inner", "corner_di", "corner_pi")
TIP_EXTRA = ("distal", "corner_do")

#: :data:`INNER_SIDE` plus points 0.5, 1 and 2 mm from the inner corners with the corner's cone of
#: forces (PyBullet's collision margin rounds the links' edges: contacts within about a millimetre
#: of a corner carry normals tilted by a few degrees).
INNER_SIDE_ROUNDED = INNER_SIDE + tuple(f"near_{c}_{d}" for c in ("di", "pi") for d in ("0.5", "1.0", "2.0"))


def link_outline(spec: ArmSpec):
    """The link's in-plane rectangle, link frame.

    Returns:
        corners: dict name -> (2,) point, metres: ``pi`` (x=0, inner), ``po``, ``di`` (x=L, inner), ``do``.
        faces: dict face -> (corner a, corner b, inward normal (2,)) (the force on the link is along
            the inward normal: the object pushes the link away from itself).
    """
    L, w = spec.link_length, spec.link_width / 2.0
    c = {"pi": np.array([0.0, w]), "po": np.array([0.0, -w]), "di": np.array([L, w]), "do": np.array([L, -w])}
    faces = {"inner": ("pi", "di", np.array([0.0, -1.0])), "outer": ("po", "do", np.array([0.0, 1.0])),
             "distal": ("do", "di", np.array([-1.0, 0.0])), "proximal": ("po", "pi", np.array([1.0, 0.0]))}
    return c, faces


_GENERATORS: dict = {}


def _generators(spec: ArmSpec, kind: str):
    """The two generators (point (2,), unit force (2,)) of a candidate kind, link frame (kept, read
    only, per (spec, kind): a localisation asks for them hundreds of times)."""
    key = (spec, kind)
    if key not in _GENERATORS:
        gens = _make_generators(spec, kind)
        for pt, f in gens:
            pt.flags.writeable = False
            f.flags.writeable = False
        _GENERATORS[key] = gens
    return _GENERATORS[key]


def _make_generators(spec: ArmSpec, kind: str):
    c, faces = link_outline(spec)
    if kind in faces:
        a, b, n = faces[kind]
        return [(c[a], n), (c[b], n)]
    if kind.startswith("near_"):  # near_di_1.0: a point 1.0 mm from the corner along the inner face,
        # force in the corner's cone (a rounded edge: PyBullet's margin tilts normals there)
        _, name, d = kind.split("_")
        d = float(d) * 1e-3
        step = np.array([-d, 0.0]) if name[0] == "d" else np.array([d, 0.0])
        normals = [n for f, (a, b, n) in faces.items() if name in (a, b)]
        return [(c[name] + step, normals[0]), (c[name] + step, normals[1])]
    name = kind.split("_")[1]
    normals = [n for f, (a, b, n) in faces.items() if name in (a, b)]
    return [(c[name], normals[0]), (c[name], normals[1])]


@dataclass(frozen=True)
class LocalContact:
    """One localised contact (SI units).

    Attributes:
        link: link index.
        kind: one of :data:`KINDS` (a face, or a corner with an oblique force).
        point_link: (3,) the contact point in the link's frame at mid-height (z = 0), metres; for a
            face contact its centre of pressure.
        point_world: (3,) the same point, world frame.
        height_interval: (2,) z range in the link frame the point may lie in (unobservable from a
            planar chain's torques): (-H/2, H/2).
        segment_world: (2, 3) the face segment across the height at the located position, world
            frame (a safe hull input: every point of a link's face is outside the object).
        force_world: (3,) the in-plane contact force on the link, world frame, N.
        normal_world: (3,) unit in-plane direction of that force (the contact normal, pointing
            into the link).
        force_n: |force|, N.
        sigma_along_m: 1-sigma uncertainty of the position along the outline, metres, from the fit's
            covariance (0 at a corner: the position is the corner's; the force direction is what is
            uncertain there).
        along_interval_m: (lo, hi) the positions along the link, x in the link frame, metres, at
            which a single contact (face point with its normal force, or a corner with its cone)
            fits the torques within ``profile_chi2 * sigma^2`` of the best, the others held: the
            honest uncertainty where the geometry is degenerate (e.g. a straight proximal chain does
            not see the force along itself, so a face point and an oblique corner force fit alike).
    """

    link: int
    kind: str
    point_link: np.ndarray
    point_world: np.ndarray
    height_interval: tuple
    segment_world: np.ndarray
    force_world: np.ndarray
    normal_world: np.ndarray
    force_n: float
    sigma_along_m: float
    along_interval_m: tuple = (float("nan"), float("nan"))


@dataclass(frozen=True)
class Localisation:
    """The contacts found at one moment, and the fit.

    Attributes:
        contacts: the localised contacts, ordered by link.
        residual_nm: RMS torque residual of the fit, N m.
        rss0: sum of squares of the torques with no contact, N^2 m^2.
        rss: sum of squares of the fit's residual.
        sigma_nm: the torque noise the significance threshold used, N m.
    """

    contacts: tuple
    residual_nm: float
    rss0: float
    rss: float
    sigma_nm: float
    predicted: np.ndarray = field(repr=False, default=None)


def external_torques(spec: ArmSpec, q, tau_motor, T_world_base, gravity) -> np.ndarray:
    """(n,) external joint torques at a quasi-static moment: ``-(tau_motor + g(q))``, N m (the
    motor torque as reported, gravity feed-forward included)."""
    return -(np.asarray(tau_motor, float) + gravity_torques(spec, q, T_world_base, gravity))


def _columns(spec: ArmSpec, T_links: np.ndarray, link: int, kind: str) -> np.ndarray:
    """(n, 2) joint torques of a unit force at each of the kind's two generators (base frame)."""
    n = spec.n_links
    R, o = T_links[link, :2, :2], T_links[link, :2, 3]
    out = np.zeros((n, 2))
    origins = T_links[: link + 1, :2, 3]
    for g, (pt, f) in enumerate(_generators(spec, kind)):
        p = R @ pt + o
        F = R @ f
        r = p[None, :] - origins
        out[: link + 1, g] = r[:, 0] * F[1] - r[:, 1] * F[0]
    return out


def torques_of_contacts(spec: ArmSpec, q, contacts) -> np.ndarray:
    """(n,) external joint torques of in-plane forces ``contacts``: iterable of
    (link, point_link (2,) or (3,), force_link (2,) or (3,)) in the link frame (base-frame torques,
    N m).  For tests and synthetic data."""
    T = link_transforms(spec, q)
    tau = np.zeros(spec.n_links)
    for link, p, f in contacts:
        R, o = T[link, :2, :2], T[link, :2, 3]
        P = R @ np.asarray(p, float)[:2] + o
        F = R @ np.asarray(f, float)[:2]
        r = P[None, :] - T[: link + 1, :2, 3]
        tau[: link + 1] += r[:, 0] * F[1] - r[:, 1] * F[0]
    return tau


#: Largest contact force a fit may use, N: cancelling pairs of huge forces at neighbouring links
#: (the columns of a link's distal corner and the next link's proximal corner nearly coincide) are
#: not contacts.
MAX_FORCE_N = 100.0


try:  # the routine behind scipy.optimize.nnls without its input checks (the fits here are tiny:
    # measured, the checks took 8 of every 9 us of a call; a localisation makes thousands of calls)
    from scipy.optimize._slsqplib import nnls as _nnls_raw
except ImportError:  # another scipy: the public function
    _nnls_raw = None


def _nnls(A: np.ndarray, b: np.ndarray, maxiter: int):
    """``scipy.optimize.nnls(A, b, maxiter=maxiter)`` for a C-contiguous float64 (m, k) ``A`` and (m,)
    ``b`` (the same numbers: the same routine)."""
    if _nnls_raw is None:
        return nnls(A, b, maxiter=maxiter)
    x, rnorm, info = _nnls_raw(A, b, maxiter)
    if info == 3:
        raise RuntimeError("Maximum number of iterations reached.")
    return x, rnorm


_RIDGE_ROWS: dict = {}


def _ridge_rows(ridge: float, k: int) -> np.ndarray:
    """(k, k) ``sqrt(ridge) * I``, kept (read only) per (ridge, k): a localisation fits thousands of times."""
    key = (ridge, k)
    if key not in _RIDGE_ROWS:
        rows = np.sqrt(ridge) * np.eye(k)
        rows.flags.writeable = False
        _RIDGE_ROWS[key] = rows
    return _RIDGE_ROWS[key]


class _Fitter:
    """:func:`_fit_module` of ``base + [extra]`` for many ``extra`` of one width, the same numbers:
    the design matrix (base columns, ridge rows) and the padded torques are built once and only the
    extra columns are written per fit (a localisation makes thousands of such fits)."""

    def __init__(self, base: list, width: int, tau: np.ndarray, fmax: float = MAX_FORCE_N, ridge: float = 0.0):
        n = len(tau)
        kb = sum(c.shape[1] for c in base)
        k = kb + width
        rows = n + k if ridge > 0 else n
        self.A = np.zeros((rows, k))
        if base:
            np.concatenate(base, axis=1, out=self.A[:n, :kb])
        if ridge > 0:  # a small penalty on the forces: among explanations the data cannot tell apart
            # (e.g. a straight proximal chain does not see the force along itself) the gentlest wins
            self.A[n:] = _ridge_rows(ridge, k)
            self.t = np.concatenate([np.asarray(tau, dtype=np.float64), np.zeros(k)])
        else:
            self.t = np.asarray(tau, dtype=np.float64)
        self.n, self.kb, self.maxiter, self.fmax = n, kb, 50 * k, fmax

    def fit(self, extra: np.ndarray) -> tuple[np.ndarray, float]:
        """(weights (k,), residual sum of squares) with ``extra`` (n, width) as the last columns
        (the sum inf when a weight passes fmax)."""
        self.A[: self.n, self.kb:] = extra
        x, rnorm = _nnls(self.A, self.t, self.maxiter)
        if max(x.tolist()) > self.fmax:
            return x, float("inf")
        return x, float(rnorm * rnorm)

    def rss(self, extra: np.ndarray) -> float:
        """The residual sum of squares of :meth:`fit`."""
        return self.fit(extra)[1]

    def lower_bounds(self, extras: np.ndarray) -> np.ndarray:
        """(m,) a lower bound on :meth:`rss` of each of ``extras`` (m, n, width), less a safety margin.

        The unconstrained least squares residual of the same design matrix (NNLS's feasible set is
        smaller, the force cap only raises it), minus ``max(1e-9, 1e4 eps kappa) |t|^2`` with
        ``kappa = ||A||_F / sqrt(ridge)`` a bound on the matrix's condition number (the ridge rows
        keep its smallest singular value at ``sqrt(ridge)`` or above; about 4e-8 |t|^2 at the
        defaults).  The margin is an estimate of the rounding with a wide factor, not a proof;
        ``tests/test_speed.py`` checks the bound against the residual on 6,000 random fits, nearly
        parallel columns included, and the exhaustive localisation against the pruned one.  So a
        candidate whose bound exceeds a threshold cannot fit below it: :func:`localise` skips those
        fits and chooses what fitting all of them would.  Without a ridge, no bound (-inf).
        """
        m, n, kb = len(extras), self.n, self.kb
        if self.A.shape[0] == n or m == 0:  # no ridge: the matrix may be singular, no safe bound
            return np.full(m, -np.inf)
        E = np.zeros((m, self.A.shape[0], extras.shape[2]))
        E[:, :n] = extras
        E[:, n + kb:] = self.A[n + kb:, kb:]
        r0 = self.t
        if kb:  # project the base columns out (twice: classical Gram-Schmidt's re-orthogonalisation)
            Q = np.linalg.qr(self.A[:, :kb])[0]
            r0 = r0 - Q @ (Q.T @ r0)
            r0 = r0 - Q @ (Q.T @ r0)
            for _ in range(2):
                E = E - Q @ (Q.T @ E)
        drop = np.zeros(m)
        for j in range(E.shape[2]):  # orthonormalise the extra columns in turn (again twice)
            u = E[:, :, j]
            for i in range(j):
                for _ in range(2):
                    u = u - np.sum(E[:, :, i] * u, axis=1)[:, None] * E[:, :, i]
            u = u / np.linalg.norm(u, axis=1)[:, None]
            E[:, :, j] = u
            drop += (u @ r0) ** 2
        # the margin: far above the rounding of these projections, which grows with the matrix's
        # condition number (at most its Frobenius norm over the ridge's singular value floor)
        ridge_sv = float(self.A[n + kb, kb]) if extras.shape[2] else 1.0
        frob = np.sqrt(float(np.sum(self.A[:, :kb] ** 2)) + float(np.max(np.sum(extras ** 2, axis=(1, 2)))))
        rel = max(1e-9, 1e4 * np.finfo(float).eps * frob / ridge_sv)
        lb = float(r0 @ r0) - drop - rel * float(self.t @ self.t)
        return np.where(np.isnan(lb), -np.inf, lb)  # never a reason to skip a fit


def _fit_module(cols: list, tau: np.ndarray, fmax: float = MAX_FORCE_N, ridge: float = 0.0):
    """NNLS of the joint torques ``tau`` (n,) on the generator columns ``cols`` (each (n, w)), with an
    optional ridge on the weights: (weights, residual sum of squares; inf past ``fmax``)."""
    if not cols:
        return np.zeros(0), float(tau @ tau)
    return _Fitter(cols[:-1], cols[-1].shape[1], tau, fmax, ridge).fit(cols[-1])


def localise(spec: ArmSpec, q, tau_ext, T_world_base=None, sigma_nm: float = 1.0e-3, chi2_gain: float = CHI2_GAIN,
             max_contacts: int | None = None, kinds=None, swap_passes: int = 2,
             force_scale_n: float | None = 20.0, profile_chi2: float = 4.0, position_sigma_m: float = 0.0,
             links=None) -> Localisation:
    """Localise the contacts at one quasi-static moment.

    Args:
        spec: the arm.
        q: (n,) joint angles, rad.
        tau_ext: (n,) external joint torques, N m (:func:`external_torques`).
        T_world_base: (4, 4) base pose (None: identity; points then in the base frame).
        sigma_nm: torque noise (1 sigma), N m, of each joint's external torque.
        chi2_gain: a contact is kept when it lowers the residual sum of squares by at least
            ``chi2_gain * sigma_nm**2``.
        max_contacts: cap on the number of contacts (None: one per link at most).
        force_scale_n: a ridge ``(sigma_nm / force_scale_n)^2`` on the generator weights, N (None:
            none): breaks ties the torques cannot (a straight proximal chain is blind to the force
            component along itself) in favour of the smallest forces; negligible where the
            torques decide.
        position_sigma_m: model error of the joint positions, metres (e.g. the encoder's quantisation
            times a typical lever): each further contact must then also beat
            ``chi2_gain * (position_sigma_m * F_max)^2``, F_max the largest located force.
        profile_chi2: the profile threshold of :attr:`LocalContact.along_interval_m` (in sigma^2).
        kinds: the candidate kinds considered (None: :data:`INNER_SIDE_ROUNDED`; with it or
            :data:`INNER_SIDE` the tip's distal face and outer distal corner are added;
            :data:`KINDS` for every face and corner).
        links: the links a contact may lie on (None: every link).

    Returns:
        a :class:`Localisation`.
    """
    kinds = INNER_SIDE_ROUNDED if kinds is None else kinds
    q = np.asarray(q, float)
    tau = np.asarray(tau_ext, float)
    n = spec.n_links
    T_base = np.eye(4) if T_world_base is None else np.asarray(T_world_base, float)
    Tl = link_transforms(spec, q)  # base frame: the torques are about the base z axis
    thresh = chi2_gain * sigma_nm ** 2
    sig = np.flatnonzero(np.abs(tau) > 3.0 * sigma_nm)
    rss0 = float(tau @ tau)
    if len(sig) == 0 or rss0 < thresh:
        return Localisation((), float(np.sqrt(rss0 / n)), rss0, rss0, sigma_nm, np.zeros(n))
    top = min(n - 1, int(sig[-1]) + 1)
    cache = {}

    def col(c):
        if c not in cache:
            cache[c] = _columns(spec, Tl, *c)
        return cache[c]

    ridge = (sigma_nm / force_scale_n) ** 2 if force_scale_n else 0.0

    def _fit(cols, t):  # noqa: F811 (the module's fit with this call's ridge)
        return _fit_module(cols, t, ridge=ridge)

    cand = [(i, k) for i in range(top + 1) for k in kinds]
    if tuple(kinds) in (INNER_SIDE, INNER_SIDE_ROUNDED) and top == n - 1:
        cand += [(n - 1, k) for k in TIP_EXTRA]
    if links is not None:
        cand = [c for c in cand if c[0] in set(links)]
    cap = n if max_contacts is None else max_contacts
    stacked = []

    def cand_cols():  # (len(cand), n, 2) every candidate's columns
        if not stacked:
            stacked.append(np.stack([col(c) for c in cand]) if cand else np.zeros((0, n, 2)))
        return stacked[0]

    def rss_of(cs):
        return _fit([col(c) for c in cs], tau)[1]

    def best_swap(cs, m, r):
        """Re-choose contact m of cs with the others fixed; returns (cs, rss)."""
        others = cs[:m] + cs[m + 1:]
        used = {c[0] for c in others}
        fit = _Fitter([col(c) for c in others], 2, tau, ridge=ridge)
        lb = fit.lower_bounds(cand_cols())
        best, best_r = cs[m], r
        for i in np.flatnonzero(lb < r - 1e-18).tolist():  # best_r only falls: the others never win
            c = cand[i]
            if c[0] in used or c == cs[m] or not lb[i] < best_r - 1e-18:
                continue
            rr = fit.rss(col(c))
            if rr < best_r - 1e-18:
                best, best_r = c, rr
        return others[:m] + [best] + others[m:], best_r

    def polish(cs, r):
        for _ in range(swap_passes):
            changed = False
            for m in range(len(cs)):
                cs2, r2 = best_swap(cs, m, r)
                if r2 < r - 1e-18:
                    cs, r, changed = cs2, r2, True
            if not changed:
                break
        return cs, r

    def thresh_of(cs):
        """The significance threshold: torque noise, plus the model error that grows with the
        force (angle quantisation moves the modelled joints by about ``position_sigma_m``)."""
        if not position_sigma_m or not cs:
            return thresh
        x = _fit([col(c) for c in cs], tau)[0]
        fmax = float(np.max(x.reshape(-1, 2).sum(axis=1)))
        return chi2_gain * (sigma_nm ** 2 + (position_sigma_m * fmax) ** 2)

    # local search on rss + thresh * (number of contacts): greedy additions with swaps, then
    # removals (each followed by re-choosing the others: two contacts may merge into one)
    chosen: list = []
    rss = rss0
    while len(chosen) < cap:
        used = {c[0] for c in chosen}
        fit = _Fitter([col(c) for c in chosen], 2, tau, ridge=ridge)
        lb = fit.lower_bounds(cand_cols())
        free = [i for i, c in enumerate(cand) if c[0] not in used]
        # the first best of the scan below, found sooner: the candidate of the lowest bound fitted
        # first, then only those whose bound is below both (the others fit worse than it)
        first = min(free, key=lambda i: lb[i]) if free else None
        known = {first: fit.rss(col(cand[first]))} if free else {}
        cut = min(rss, known.get(first, rss))
        best, best_rss = None, rss
        for i in free:
            if not lb[i] <= cut:
                continue
            c = cand[i]
            r = known[i] if i in known else fit.rss(col(c))
            if r < best_rss:
                best, best_rss = c, r
        if best is None or rss - best_rss < thresh_of(chosen + [best]):
            break
        chosen, rss = polish(chosen + [best], best_rss)
    thresh = thresh_of(chosen)
    improved = True
    while improved and chosen:
        improved = False
        for m in range(len(chosen)):
            cs = chosen[:m] + chosen[m + 1:]
            cs, r = polish(cs, rss_of(cs))
            if r + thresh * len(cs) < rss + thresh * len(chosen):
                chosen, rss, improved = cs, r, True
                break
    chosen.sort()
    x, rss = _fit([col(c) for c in chosen], tau)
    A = np.concatenate([col(c) for c in chosen], axis=1) if chosen else np.zeros((n, 0))
    pred = A @ x if chosen else np.zeros(n)
    rss = float(np.sum((tau - pred) ** 2))
    # covariance on the active generators
    active = x > 1e-12
    cov = np.zeros((len(x), len(x)))
    if active.any():
        Aa = A[:, active]
        try:
            cov_a = sigma_nm ** 2 * np.linalg.inv(Aa.T @ Aa + ridge * np.eye(Aa.shape[1]))
        except np.linalg.LinAlgError:
            cov_a = sigma_nm ** 2 * np.linalg.pinv(Aa.T @ Aa + ridge * np.eye(Aa.shape[1]))
        idx = np.flatnonzero(active)
        cov[np.ix_(idx, idx)] = cov_a
    # profile of the fit along each contact's link: a point contact at each x of the inner face
    # (its normal force) and the two inner corners (their cones), the other contacts refitted
    prof_x = np.linspace(0.0, spec.link_length, 401)

    def profile(m, x_est):
        link = chosen[m][0]
        base = [col(c) for c in chosen[:m] + chosen[m + 1:]]
        R, o = Tl[link, :2, :2], Tl[link, :2, 3]
        F = R @ np.array([0.0, -1.0])
        origins = Tl[: link + 1, :2, 3]
        best = _fit(base + [col(chosen[m])], tau)[1]
        # the inner face's point at every x at once: (len(prof_x), n) joint torques of a unit force
        P = (R @ np.stack([prof_x, np.full(len(prof_x), spec.link_width / 2)])).T + o
        r = P[:, None, :] - origins[None, :, :]
        C = np.zeros((len(prof_x), n, 1))
        C[:, : link + 1, 0] = r[..., 0] * F[1] - r[..., 1] * F[0]
        fit1, fit2 = _Fitter(base, 1, tau, ridge=ridge), _Fitter(base, 2, tau, ridge=ridge)
        limit = best + profile_chi2 * sigma_nm ** 2
        lb = fit1.lower_bounds(C)  # the points whose bound passes the limit cannot fit

        def fits(i):  # the point at prof_x[i] (the corners' cones at the ends) fits within the limit
            x = prof_x[i]
            if x == 0.0:
                rr = fit2.rss(col((link, "corner_pi")))
            elif x == spec.link_length:
                rr = fit2.rss(col((link, "corner_di")))
            elif not lb[i] <= limit:
                return False
            else:
                rr = fit1.rss(C[i])
            return rr <= limit

        # the interval is min and max of x_est and the points that fit: scanned inwards from each
        # end up to x_est, the first that fits decides that side (the points beyond cannot change it)
        lo = next((float(prof_x[i]) for i in range(len(prof_x)) if prof_x[i] < x_est and fits(i)), x_est)
        hi = next((float(prof_x[i]) for i in range(len(prof_x) - 1, -1, -1) if prof_x[i] > x_est and fits(i)), x_est)
        return lo, hi

    contacts = []
    H = spec.link_height
    for m, (link, kind) in enumerate(chosen):
        w = x[2 * m: 2 * m + 2]
        C = cov[2 * m: 2 * m + 2, 2 * m: 2 * m + 2]
        (pa, fa), (pb, fb) = _generators(spec, kind)
        tot = float(w.sum())
        if tot <= 0:
            continue
        if kind.startswith(("corner", "near")):
            p2 = pa
            f2 = w[0] * fa + w[1] * fb
            sig_s = 0.0
        else:
            t = w[1] / tot
            p2 = pa + t * (pb - pa)
            f2 = tot * fa
            seg = float(np.linalg.norm(pb - pa))
            # s = seg * wb / (wa + wb): gradient (-seg wb, seg wa) / tot^2
            g = seg * np.array([-w[1], w[0]]) / tot ** 2
            sig_s = float(np.sqrt(max(g @ C @ g, 0.0)))
        p_link = np.array([p2[0], p2[1], 0.0])
        Tw = T_base @ Tl[link]
        pw = Tw[:3, :3] @ p_link + Tw[:3, 3]
        Fw = Tw[:3, :3] @ np.array([f2[0], f2[1], 0.0])
        fn = float(np.linalg.norm(Fw))
        seg_w = np.array([Tw[:3, :3] @ (p_link + [0, 0, z]) + Tw[:3, 3] for z in (-H / 2, H / 2)])
        iv = profile(m, float(p_link[0])) if kind in INNER_SIDE_ROUNDED else (float("nan"), float("nan"))
        contacts.append(LocalContact(link=int(link), kind=kind, point_link=p_link, point_world=pw,
                                     height_interval=(-H / 2, H / 2), segment_world=seg_w, force_world=Fw,
                                     normal_world=Fw / fn if fn > 0 else Fw, force_n=fn, sigma_along_m=sig_s,
                                     along_interval_m=iv))
    return Localisation(tuple(contacts), float(np.sqrt(rss / n)), rss0, rss, sigma_nm, pred)


def inverse_dynamics(spec: ArmSpec, q, dq, ddq) -> np.ndarray:
    """(n,) joint torques, N m, that move the planar chain (no gravity, no contact) with angles
    ``q``, velocities ``dq`` and accelerations ``ddq`` (n,) each (Newton-Euler; link i a uniform box
    of mass m, centre of mass at mid-link, inertia m (L^2 + W^2) / 12 about z).  The external torques
    of the contacts at a moving moment are then ``inverse_dynamics - (tau_motor + g(q))``."""
    q, dq, ddq = (np.asarray(v, float) for v in (q, dq, ddq))
    n, L, m = spec.n_links, spec.link_length, spec.link_mass
    I = m * (L * L + spec.link_width ** 2) / 12.0
    th, w, al = np.cumsum(q), np.cumsum(dq), np.cumsum(ddq)
    e = np.stack([np.cos(th), np.sin(th)], axis=1)
    perp = np.stack([-e[:, 1], e[:, 0]], axis=1)
    a_o = np.zeros((n + 1, 2))
    for i in range(n):
        a_o[i + 1] = a_o[i] + L * (al[i] * perp[i] - w[i] ** 2 * e[i])
    a_c = a_o[:n] + (L / 2) * (al[:, None] * perp - (w ** 2)[:, None] * e)
    f_next, n_next = np.zeros(2), 0.0
    tau = np.zeros(n)
    for i in range(n - 1, -1, -1):
        f_i = m * a_c[i] + f_next  # force on link i from link i-1 at joint i
        r_o = -(L / 2) * e[i]  # joint i relative to the centre of mass
        r_n = (L / 2) * e[i]  # joint i+1 relative to the centre of mass
        cr = lambda r, f: r[0] * f[1] - r[1] * f[0]
        n_i = I * al[i] + n_next - cr(r_o, f_i) + cr(r_n, f_next)
        tau[i] = n_i
        f_next, n_next = f_i, n_i
    return tau
