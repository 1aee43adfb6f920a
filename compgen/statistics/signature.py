"""First-order signatures of effects on poses: what a unit of each effect's parameters does
to every reading (basis × the gain of its slot in the chain), and the triangular factors of
their columns, stacked over poses a chunk at a time so that memory stays as fit's."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..model.effects import Effect
from ..model.kinematics import SlotGains, coordinate, effect_gains, in_halves
from ..model.machine import Machine
from ..model.poses import Poses

CHUNK_BYTES = 24 << 20  # the basis values of every candidate held at once: a BLOCK of ~300 columns at once
BLOCK = 8192           # poses a walk of the chain serves: its slots' gains held
SMALLEST = 1024        # poses a walk serves at least (a walk has its cost in Python as well)


def _block(n: int) -> int:
    """Poses a walk of the chain serves in a session of ``n``: ``BLOCK``, or a sixteenth of a
    smaller session, so that what the walks hold (two at once, one per half) grows with the
    session as fit's memory does: BLOCK's frames alone were 60 MiB beside fit's 32 at 21 690
    poses."""
    return min(BLOCK, max(SMALLEST, n // 16))


def columns(machine: Machine, poses: Poses, effects: Sequence[Effect]) -> np.ndarray:
    """First-order signatures of the effects' parameters, (3n, Σ params), mm per unit, in
    the order of ``effects``; a walk of the chains a block of poses at a time, in halves
    (one walk of a dense session's every pose at once is fresh memory at every link)."""
    x = _coordinates(machine, poses, effects)
    block = _block(len(poses))
    halves = in_halves(lambda starts: [_columns_at(machine, poses, effects, x, slice(a, a + block))
                                       for a in starts], range(0, len(poses), block))
    blocks = [b for half in halves for b in half]
    return np.concatenate(blocks) if blocks else np.zeros((0, sum(len(e.params) for e in effects)))


def r_factor(machine: Machine, poses: Poses, effects: Sequence[Effect],
              start: np.ndarray | None = None, chunk: int | None = None) -> np.ndarray:
    """R of the QR factorisation of the effects' columns on ``poses`` stacked under ``start``
    (R of stacked rows is R of the stacked R factors: the halves' are made apart)."""
    x = _coordinates(machine, poses, effects)
    chunk = chunk or _block(len(poses))

    def part(blocks: range) -> np.ndarray | None:
        R = None
        for i in blocks:
            block = _columns_at(machine, poses, effects, x, slice(i, i + chunk))
            R = np.linalg.qr(block if R is None else np.vstack([R, block]), mode="r")
        return R

    parts = [R for R in (start, *in_halves(part, range(0, len(poses), chunk))) if R is not None]
    return parts[0] if len(parts) == 1 else np.linalg.qr(np.vstack(parts), mode="r")


def _coordinates(machine: Machine, poses: Poses, effects: Sequence[Effect]) -> list[np.ndarray]:
    """Each effect's coordinate on the whole session: a reversal's side depends on its run
    (a block of it would take its first pose's side from the block's first move)."""
    return [coordinate(machine, e, poses) for e in effects]


def _columns_at(machine: Machine, poses: Poses, effects: Sequence[Effect], x: Sequence[np.ndarray],
                at: slice) -> np.ndarray:
    """The effects' columns on the poses ``at`` from one walk, ``x`` their coordinates."""
    gains, made = SlotGains(machine, poses.take(at)), {}
    return np.column_stack([effect_gains(gains, e, c[at], made).reshape(-1, len(e.params))
                            for e, c in zip(effects, x, strict=True)])


def _where(e: Effect) -> tuple:
    """What an effect's coordinate depends on: its axis and basis kind; the time alone for a
    warming; a scale in time's τ too."""
    kind = e.basis.kind
    if kind == "e":
        return ("time", "e")
    return (e.carrier, kind, e.basis.order) if kind == "g" else (e.carrier, kind)


def products(machine: Machine, poses: Poses, effects: Sequence[Effect], Q: np.ndarray | Sequence[np.ndarray],
             r: np.ndarray,
             noise: tuple[np.ndarray, np.ndarray] | None = None) -> dict[str, tuple]:
    """Each effect's first-order signature c, reduced to what diagnose needs of it: cᵀc
    (k × k), Qᵀc (p × k) and cᵀr (k), over blocks of poses: a dense session's columns are
    millions of rows, never made. ``Q`` (3n, p), or blocks of it side by side ([Q | more]
    without a copy of Q: 240 MB at 720 000 readings), and ``r`` (3n,) are in (n, 3) reading
    order. With ``noise`` = (segments, ρ (n, 3)), the columns are taken white (Prais–Winsten
    W), as Q and r must already be.

    A column is its basis values v (one number per pose) times its slot's gain g (a 3-vector
    per pose; an effect of two directions, the sum of two such), so its products follow
    from each slot's own, made once per pose for every effect on it: Qᵀc = vᵀ(g·WᵀQ),
    cᵀr = vᵀ(g·Wᵀr) and cᵀc = Σ vᵢvⱼ gᵢ·(WᵀW)gⱼ, WᵀW tridiagonal within a segment (a pose
    and the next): no K × 3n matrix of columns is made."""
    if not effects:          # every one's columns made before (diagnose's step 3): none to walk
        return {}
    coords: dict = {}
    for e in effects:        # on the whole session: a reversal's side depends on its run
        if _where(e) not in coords:
            coords[_where(e)] = coordinate(machine, e, poses)
    n = len(poses)
    Qs = [Q] if isinstance(Q, np.ndarray) else list(Q)     # [Q | more] without copying Q
    edges = np.cumsum([0, *(q.shape[1] for q in Qs)])
    q_rows = [slice(lo, hi) for lo, hi in zip(edges[:-1], edges[1:], strict=True)]   # qc's rows per block
    slots = list(dict.fromkeys((e.carrier, e.slot, d) for e in effects for d in e.direction))
    groups: dict[tuple[int, ...], list[int]] = {}          # effects on the same slots, side by side
    for i, e in enumerate(effects):
        groups.setdefault(tuple(slots.index((e.carrier, e.slot, d)) for d in e.direction), []).append(i)
    cols, spans, K = {}, {}, 0
    for g, members in groups.items():
        lo = K
        for i in members:
            cols[i] = (K, K + len(effects[i].params))
            K = cols[i][1]
        spans[g] = (lo, K)
    # the basis values each group's columns are, per slot of the group: where in the
    # distinct bases' values side by side, and a compound's sign (``Effect.split`` of the
    # identity: a signed selection of its terms, (cos, −sin) and (sin, cos) turned by sense)
    bases = list(dict.fromkeys((_where(e), e.basis) for e in effects))
    first_col = np.cumsum([0, *(len(basis.terms) for _, basis in bases)])
    taken: dict = {}
    for g, members in groups.items():
        picks: list[list] = [[] for _ in g]
        for i in members:
            e = effects[i]
            j = bases.index((_where(e), e.basis))
            own = np.arange(first_col[j], first_col[j + 1])
            for t, (_, M) in enumerate(e.split(np.eye(len(own)))):
                if not ((M != 0).sum(axis=0) == 1).all():
                    raise ValueError(f"{e.name}: a part that is not a signed choice of its terms")
                row = np.abs(M).argmax(axis=0)
                picks[t].append((own[row], M[row, np.arange(M.shape[1])]))
        taken[g] = [(np.concatenate([p for p, _ in pick]),
                     None if len(g) == 1 else np.concatenate([s for _, s in pick])) for pick in picks]
    white = noise is not None
    if white:
        seg, rho = noise
        same = seg[1:] == seg[:-1]                 # a reading and the next in one segment
        off = np.zeros((n, 3))                     # (WᵀW)ₘ,ₘ₊₁ per direction, = Wₘ₊₁,ₘ = −ρₘ₊₁
        off[:-1] = np.where(same[:, None], -rho[1:], 0.0)
        first = np.r_[True, ~same]
        gram = np.where(first[:, None], 1 - rho**2, 1.0) + off**2        # (WᵀW)ₘ,ₘ
        diag = np.where(first[:, None], np.sqrt(1 - rho**2), 1.0)       # Wₘ,ₘ
    chunk = max(64, CHUNK_BYTES // (8 * max(K, 1)))
    block = _block(n)

    def part(blocks: range) -> tuple:
        """The sums over these blocks' poses."""
        qc, cr = np.zeros((edges[-1], K)), np.zeros(K)
        cc = {g: np.zeros((hi - lo, hi - lo)) for g, (lo, hi) in spans.items()}
        lag = {g: np.zeros((hi - lo, hi - lo)) for g, (lo, hi) in spans.items()}    # F of F + Fᵀ
        for a in blocks:
            stop = min(a + block, n)
            gains = SlotGains(machine, poses.take(slice(a, min(stop + 1, n) if white else stop)))
            G_all = np.stack([gains(k) for k in slots], axis=1)      # (poses, slots, 3)
            for b in range(a, stop, chunk):
                end = min(b + chunk, stop)
                m = end - b
                pairs = min(end + 1, n) - b - 1 if white else 0      # a pose and the next
                rows = max(m, pairs + 1)                             # white: with the next pose
                G = G_all[b - a:b - a + rows]
                Gm = G[:m]
                # each block of Q on its own, as Qᵀc of the model's Q must not depend on what is
                # carried beside it (a screened pass and a plain one give the same numbers)
                Ys = [q[3 * b:3 * end].reshape(m, 3, q.shape[1]) for q in Qs]   # a Q may have no column
                y = r[3 * b:3 * end].reshape(m, 3)
                if white:                      # WᵀY, as Qᵀ_w C_w = (WᵀQ_w)ᵀ C
                    Ys = [_transposed_white(q, diag, off, b, end, pairs) for q in Qs]
                    y = _transposed_white(r[:, None], diag, off, b, end, pairs)[..., 0]
                gq = [Gm @ Y for Y in Ys]                            # (m, slots, p): g·WᵀY
                gr = (Gm @ y[:, :, None])[..., 0]
                Gw = Gm * gram[b:end, None] if white else Gm
                w0 = np.einsum("msd,msd->ms", Gw, Gm)               # g·(WᵀW)g per pose
                if pairs:                                            # gₘ·(WᵀW)ₘ,ₘ₊₁gₘ₊₁
                    w1 = np.einsum("msd,msd->ms", G[:pairs] * off[b:b + pairs, None], G[1:pairs + 1])
                # every distinct basis once, side by side; each group's columns taken from them
                values = np.concatenate([basis.values(coords[at][b:b + rows]) for at, basis in bases], axis=1)
                for g in groups:
                    V = [values[:, pick] if sign is None else values[:, pick] * sign
                         for pick, sign in taken[g]]
                    lo, hi = spans[g]
                    if len(g) > 1:     # two directions: as columns, where they cancel (as they may) exactly
                        c = G[:, g[0], :, None] * V[0][:, None, :]
                        c += G[:, g[1], :, None] * V[1][:, None, :]
                        flat = c[:m].reshape(3 * m, -1)
                        for at, Y in zip(q_rows, Ys, strict=True):
                            qc[at, lo:hi] += Y.reshape(3 * m, -1).T @ flat
                        cr[lo:hi] += y.ravel() @ flat
                        cc[g] += flat.T @ (gram[b:end].reshape(-1, 1) * flat if white else flat)
                        if pairs:
                            lag[g] += (off[b:b + pairs, :, None] * c[:pairs]).reshape(3 * pairs, -1).T \
                                @ c[1:pairs + 1].reshape(3 * pairs, -1)
                        continue
                    s, v = g[0], V[0]
                    for at, g_q in zip(q_rows, gq, strict=True):
                        qc[at, lo:hi] += g_q[:, s].T @ v[:m]
                    cr[lo:hi] += gr[:, s] @ v[:m]
                    cc[g] += v[:m].T @ (w0[:, s, None] * v[:m])
                    if pairs:
                        lag[g] += v[:pairs].T @ (w1[:, s, None] * v[1:pairs + 1])
        return qc, cr, cc, lag

    sums = in_halves(part, range(0, n, block))
    qc, cr = sum(t[0] for t in sums), sum(t[1] for t in sums)
    cc = {g: sum(t[2][g] for t in sums) for g in spans}
    lag = {g: sum(t[3][g] for t in sums) for g in spans}
    out = {}
    for g, members in groups.items():
        whole = cc[g] + lag[g] + lag[g].T
        # a sum of squares, made white from a pose's products with the next: where the white
        # column is nothing, rounding may leave it a few ulps of its parts below zero
        np.fill_diagonal(whole, np.maximum(np.diagonal(whole), 0.0))
        for i in members:
            lo, hi = cols[i]
            at = slice(lo - spans[g][0], hi - spans[g][0])
            out[effects[i].name] = (whole[at, at], qc[:, lo:hi], cr[lo:hi])
    return {e.name: out[e.name] for e in effects}


def _transposed_white(q: np.ndarray, diag: np.ndarray, off: np.ndarray, b: int, end: int,
                      pairs: int) -> np.ndarray:
    """Rows b..end of Wᵀq, (end − b, 3, columns), for q (3n, columns) in (n, 3) reading
    order: each reading's Wₘ,ₘ times itself, plus Wₘ₊₁,ₘ (``off``) times the next reading
    in its segment (``pairs`` of them here)."""
    m = end - b
    k = q.shape[1]                  # it may be 0: a Q with no column (reshape's -1 cannot say)
    out = diag[b:end, :, None] * q[3 * b:3 * end].reshape(m, 3, k)
    out[:pairs] += off[b:b + pairs, :, None] * q[3 * b + 3:3 * (b + 1 + pairs)].reshape(pairs, 3, k)
    return out
