"""The engine's scheduler: persistent workers that run a model's stages over the rows of a frame.

A lane kernel (the fast CPU path) is one call of the workers that ``workers(plan)`` builds
for the model's :class:`Plan`, a tuple of stages bound when the kernel is built. The scheduler owns the
worker loop, the phase numbers, row claiming, the barriers between phases and the
convergence gates of an iterative solve; a stage only says what to do with a chunk of
rows: ``stage(ctx, i0, i1, j)`` (``ctx``: the kernel's named arguments, a
:func:`context`; ``j``: the update, or for the stages after the updates the number of
updates run).

A plan runs, in one launch:

1. ``before`` stages (when ``runs_before(ctx)``), each one phase and a barrier;
2. up to ``n`` updates, each the ``update`` stages one after another (one phase each,
   barriers between them), gated by the residuals the stages leave in ``rbuf[j, 0:2]``:
   update ``j`` runs only while no earlier one converged (every residual ``<= tol``)
   or grew (``> grow`` times the best);
3. ``after`` stages, when the updates converged (always, for a plan without updates),
   barriers between them.
"""

import functools
from types import SimpleNamespace

from . import common
from .common import MAX_STEPS, context, namespace  # noqa: F401 - context: part of the interface

# -- persistent workers ------------------------------------------------------------
# taichi launches a parallel loop through a thread pool whose hand-off costs ~50 us
# per loop on these machines, and a second pool thread often starts hundreds of us
# after the first. A solve kernel therefore runs ONE parallel loop of ``nw``
# persistent workers (one per pool thread) for all its updates: the workers claim
# chunks of rows of each phase (an update, or a pass of one) from atomic counters and
# wait for the previous phase to finish before they start the next one. The rows are
# cut into ``nw`` bands; a worker takes chunks of its own band first (its rows stay in
# its core's cache from update to update), then helps with the others, so a worker
# that starts late costs nothing. Rows of a phase are claimed only after every row of
# the phase before, and a claimed row is worked on by a running worker, so the waits
# always end: with one pool thread the first worker simply does everything. A CPU pool
# thread takes a chunk of at least WORKER_STRIDE consecutive loop indices, so the
# workers sit WORKER_STRIDE indices apart.

WORKER_STRIDE = 512
MAX_WORKERS = 32
SYNC_STRIDE = 16  # i32 slots between two counters: one 64-byte cache line each
ROWS_PER_CLAIM = 2
#: Sub-phases of one update, at most (C-DNF's Summation update: the row pass, then the rest).
MAX_UPDATE_PHASES = 2
#: Phases of one launch: the updates', then those after them, the ones before them counting down from the last.
MAX_PHASES = MAX_UPDATE_PHASES * MAX_STEPS + 3


def sync_size() -> int:
    """Length of the counter field a solve kernel needs."""
    return MAX_PHASES * (MAX_WORKERS + 1) * SYNC_STRIDE


class Plan:
    """A model's stages for the scheduler (compile-time; see the module docstring).

    Parameters
    ----------
    update : tuple of ti.func
        The stages of one update (at most :data:`MAX_UPDATE_PHASES`); empty: no iteration.
    before, after : tuple of ti.func
        Stages before the updates, and after them (when they converged).
    runs_before : ti.func or None
        ``runs_before(ctx)``: whether the ``before`` stages run in this launch (None: always).
    controls : ti.func or None
        ``controls(ctx) -> (nw, H, n, tol, grow)``: the launch's workers, rows, updates at most
        and stopping rule, read from the context by name (needed by :func:`workers`).
    """

    def __init__(self, update=(), before=(), after=(), runs_before=None, controls=None):
        if len(update) > MAX_UPDATE_PHASES:
            raise ValueError(f"at most {MAX_UPDATE_PHASES} stages per update, got {len(update)}")
        if len(update) * MAX_STEPS + len(after) + len(before) > MAX_PHASES:
            raise ValueError("too many stages for the phase counters (MAX_PHASES)")
        self.update, self.before, self.after = tuple(update), tuple(before), tuple(after)
        self.runs_before = runs_before
        self.conditional = runs_before is not None
        self.controls = controls


@functools.lru_cache(maxsize=None)
def build(ti, lanes: int) -> SimpleNamespace:
    """The scheduler for the DSL module ``ti`` (see :func:`cdnf_ti.kernels.common.build`).

    Also makes the process's one set of worker scratch, which the kernels reach through this
    namespace (never as arguments): the phase counters ``sync`` (int32, :func:`sync_size`), the
    per-update residuals ``rbuf`` (float32, (MAX_STEPS, 2)) and a launch's float64 sum and flag
    ``msum``. The backends serialise the launches that use them (``Scratch.lock``).
    """
    go_on = common.build(ti, lanes).go_on
    sync = ti.field(ti.i32, sync_size())
    rbuf = ti.field(ti.f32, (MAX_STEPS, 2))
    msum = ti.field(ti.f64, 2)

    @ti.func
    def _slot(phase, k):
        """Counter ``k`` of ``phase``: the claim counter of band ``k < MAX_WORKERS``, else the done counter."""
        return (phase * (MAX_WORKERS + 1) + k) * SYNC_STRIDE


    @ti.func
    def reset_sync(nw):
        """Zero the phase counters, mark every update not run (serial: before the workers start)."""
        ti.loop_config(serialize=True)
        for q in range(MAX_PHASES):
            for k in range(nw):
                sync[_slot(q, k)] = 0
            sync[_slot(q, MAX_WORKERS)] = 0
            if q < MAX_STEPS:
                rbuf[q, 0] = -1.0  # < 0: update not run
                rbuf[q, 1] = -1.0


    @ti.func
    def claim_rows(phase, w, nw, H):
        """Rows ``[i0, i1)`` of the next chunk of ``phase`` for worker ``w`` (``i0 >= i1``: none left)."""
        i0 = H
        i1 = H
        for t in range(nw):
            if i0 >= i1:
                band = (w + t) % nw
                top = band * H // nw
                end = (band + 1) * H // nw
                x = top + ti.atomic_add(sync[_slot(phase, band)], ROWS_PER_CLAIM)
                if x < end:
                    i0 = x
                    i1 = ti.min(x + ROWS_PER_CLAIM, end)
        return i0, i1


    @ti.func
    def finish_rows(phase, rows):
        ti.atomic_add(sync[_slot(phase, MAX_WORKERS)], rows)


    @ti.func
    def wait_phase(phase, H):
        """Spin until every row of ``phase`` is finished."""
        while ti.atomic_add(sync[_slot(phase, MAX_WORKERS)], 0) < H:
            pass


    @ti.func
    def worker_start():
        """A worker's ``(go, ran, best)`` before its first update: go on, none run, no residual yet."""
        return 1, 0, ti.f32(3.0e38)


    @ti.func
    def gate(go, best, j, phase, H, tol, grow):
        """Before update ``j``: wait until ``phase`` (the last of update ``j - 1``) is finished, then
        decide whether to run update ``j`` (:func:`_go_on`). Returns ``(go, best)``."""
        if go != 0 and j > 0:
            wait_phase(phase, H)
            go, best = go_on(ti.max(rbuf[j - 1, 0], rbuf[j - 1, 1]), best, tol, grow)
        return go, best


    @ti.func
    def converged(go, ran, phase, H, tol):
        """Whether the solve converged in this launch (``ran`` updates run; ``phase``: the last one's).

        A worker that ran every update first waits for the last one to finish.
        """
        if go != 0 and ran > 0:
            wait_phase(phase, H)
        last = ti.max(ran - 1, 0)
        return (ran > 0) & (ti.max(rbuf[last, 0], rbuf[last, 1]) <= tol)

    @ti.func
    def residuals_to(record: ti.template(), fields: ti.template()):
        """Copy the residuals of the launch (``rbuf[j, f]``, -1: not run) into its ``record`` (the
        kernel's serial tail, after the workers; :class:`~cdnf_ti.kernels.common.LaunchRecord`)."""
        for j in ti.static(range(MAX_STEPS)):
            for f in ti.static(range(fields)):
                record[j, common.RECORD_COEFS + f] = rbuf[j, f]

    def workers(plan: Plan):
        """The persistent workers that run ``plan``: a ``ti.func`` ``run(ctx)``, the kernel's parallel loop.

        ``plan.controls(ctx)`` gives the launch's workers, rows, updates at most and stopping rule
        (see the module docstring); the stages max their residuals into ``rbuf`` (set to -1 here).
        Call ``run(ctx)`` at the kernel's top level, after any serial set-up and before the serial
        tail (e.g. :func:`residuals_to`). The plan is bound here, when the kernel is built.
        """
        if plan.controls is None:
            raise ValueError("a plan run by workers needs controls(ctx)")

        @ti.func
        def _phase(stage: ti.template(), ctx: ti.template(), phase, w, j):
            """Worker ``w``'s part of ``phase``: ``stage(ctx, i0, i1, j)`` on each chunk of rows it claims."""
            nw, H, n_, tol_, grow_ = plan.controls(ctx)
            while True:
                i0, i1 = claim_rows(phase, w, nw, H)
                if i0 >= i1:
                    break
                stage(ctx, i0, i1, j)
                finish_rows(phase, i1 - i0)

        @ti.func
        def run(ctx: ti.template()):
            nw, H, n, tol, grow = plan.controls(ctx)
            reset_sync(nw)
            per = ti.static(len(plan.update))
            after = ti.static(per * MAX_STEPS)  # the first phase after the updates
            for slot in range(nw * WORKER_STRIDE):
                if slot % WORKER_STRIDE == 0:
                    w = slot // WORKER_STRIDE
                    go_before = 1
                    if ti.static(plan.conditional):
                        go_before = plan.runs_before(ctx)
                    for k in ti.static(range(len(plan.before))):
                        if go_before != 0:
                            _phase(plan.before[k], ctx, MAX_PHASES - 1 - k, w, 0)
                            wait_phase(MAX_PHASES - 1 - k, H)
                    done = 1
                    ran = 0
                    if ti.static(per > 0):
                        go, ran_, best = worker_start()
                        for j in range(n):
                            go, best = gate(go, best, j, per * j - 1, H, tol, grow)
                            if go != 0:
                                ran_ = j + 1
                                for s in ti.static(range(per)):
                                    if ti.static(s > 0):
                                        wait_phase(per * j + s - 1, H)
                                    _phase(plan.update[s], ctx, per * j + s, w, j)
                        ran = ran_
                        done = ti.select(converged(go, ran, per * ran - 1, H, tol), 1, 0)
                    if done != 0:
                        for k in ti.static(range(len(plan.after))):
                            if ti.static(k > 0):
                                wait_phase(after + k - 1, H)
                            _phase(plan.after[k], ctx, after + k, w, ran)

        return run

    return namespace(globals(), locals())
