"""The bookkeeping of :func:`.settle.settle` between two blocks of marching, compiled (issue 32):
which trajectories' returns shrink (the seeds of Newton), and how far each section is from a known
orbit.

``settle`` looks at every open trajectory after each block: the returns over every order at the
start and at the end of its history, and the distance of each of its sections to each known orbit.
Written with numpy, each look built arrays of ``periods x trajectories x orders x 4``: in the
default ``fractions`` (one process), the labelling took 12.6 s and the screen about 13 s of the 66 s
spent beside the kernel's 229 s; compiled, 4.5 s and 2.9 s (``docs/benchmarks.md``). These loops do the
same arithmetic on the same numbers, element by element (``|(a - b) s|``, ``|a s - o|``), with
numpy's rules for NaN (a largest or smallest value is NaN when any is; the first NaN is the
smallest), so they give numpy's answers bit for bit. They are compiled with the kernel, in its
cache (:mod:`.kernel`), for the CPU only: the history is kept on the host.
"""

from .kernel_phases import NAN, fmax


def largest4(a, b, c, d):
    """numpy's ``max`` of four values: NaN when any is (the kernel's :func:`.kernel_phases.fmax`)."""
    return fmax(fmax(a, b), fmax(c, d))


def shrinking_returns(sections, scale, open_, most, reach):
    """``(most, n)``: whether trajectory ``j``'s return over the order ``k + 1`` shrank by half over
    its history ``sections`` ((periods, n, 4), scaled by ``scale`` (n, 4)) and ends within ``reach``
    times its size (``settle._find_orbits``); False for a trajectory not ``open_``."""
    span, n = sections.shape[0], sections.shape[1]
    out = np.zeros((most, n), np.bool_)  # noqa: F821 (a global of the compiled namespace)
    end = span - 1
    for j in range(n):
        if not open_[j]:
            continue
        s0, s1, s2, s3 = scale[j, 0], scale[j, 1], scale[j, 2], scale[j, 3]
        size = largest4(abs(sections[end, j, 0] * s0), abs(sections[end, j, 1] * s1), abs(sections[end, j, 2] * s2),
                        abs(sections[end, j, 3] * s3))
        for k in range(most):
            first = largest4(abs((sections[k + 1, j, 0] - sections[0, j, 0]) * s0),
                             abs((sections[k + 1, j, 1] - sections[0, j, 1]) * s1),
                             abs((sections[k + 1, j, 2] - sections[0, j, 2]) * s2),
                             abs((sections[k + 1, j, 3] - sections[0, j, 3]) * s3))
            back = span - 2 - k
            last = largest4(abs((sections[end, j, 0] - sections[back, j, 0]) * s0),
                            abs((sections[end, j, 1] - sections[back, j, 1]) * s1),
                            abs((sections[end, j, 2] - sections[back, j, 2]) * s2),
                            abs((sections[end, j, 3] - sections[back, j, 3]) * s3))
            out[k, j] = last < 0.5 * first and last <= reach * size
    return out


def orbit_distances(sections, scale, points):
    """The scaled distance of each section ((periods, n, 4), scaled by ``scale`` (4,)) to the
    nearest of an orbit's scaled ``points`` ((m, 4)), and that point's index
    (``settle._distances``)."""
    span, n, m = sections.shape[0], sections.shape[1], points.shape[0]
    gaps = np.empty((span, n))  # noqa: F821
    nearest = np.zeros((span, n), np.int64)  # noqa: F821
    s0, s1, s2, s3 = scale[0], scale[1], scale[2], scale[3]
    for t in range(span):
        for j in range(n):
            x0, x1 = sections[t, j, 0] * s0, sections[t, j, 1] * s1
            x2, x3 = sections[t, j, 2] * s2, sections[t, j, 3] * s3
            best = NAN
            which = 0
            for i in range(m):
                gap = largest4(abs(x0 - points[i, 0]), abs(x1 - points[i, 1]), abs(x2 - points[i, 2]),
                               abs(x3 - points[i, 3]))
                if gap != gap:  # numpy's min is NaN and its argmin the first NaN
                    best, which = gap, i
                    break
                if i == 0 or gap < best:
                    best, which = gap, i
            gaps[t, j], nearest[t, j] = best, which
    return gaps, nearest
