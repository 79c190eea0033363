"""The drawing helpers every study shares: a figure made without pyplot
(``matplotlib.figure.Figure``, written by the Agg canvas, so nothing is registered or left to
close), written to PNG, the resolution, the frequency axis's label, a load in Ohm as text, and :class:`Rendering`, which draws
a study's figures in forked processes while the study goes on. Each study's figures are in its
own package.
"""

from __future__ import annotations

from pathlib import Path



def new_figure(figsize: tuple, *grid, **kwargs):
    """A new figure and its axes (``Figure.subplots(*grid, **kwargs)``)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    return fig, fig.subplots(*grid, **kwargs)


def save_png(fig, path: Path, layout: bool = True) -> Path:
    """Lay out ``fig`` (unless its layout is fixed already), write it to ``path`` (PNG); return
    ``path``."""
    if layout:
        fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    return path


def ohms(value: float, unit: str = "Ω") -> str:
    """A resistance to 3 digits with an SI prefix: ``52 kΩ``, ``3.59 MΩ`` (``unit="Ohm"``
    for plain text)."""
    for factor, prefix in ((1e9, "G"), (1e6, "M"), (1e3, "k"), (1.0, "")):
        if value >= factor:
            return f"{value / factor:.3g} {prefix}{unit}"
    return f"{value:.3g} {unit}"


#: Resolution of every PNG.
DPI = 130
#: The label of every frequency axis: the forcing frequency over the main mass's natural frequency.
FREQUENCY = r"frequency $\omega / \omega_n$, $\omega_n = \sqrt{K/M}$"
#: The same ratio in a title or a legend.
RATIO = r"$\omega / \omega_n$"


class Rendering:
    """Figure calls (``(function, *args)``, each returning the path it wrote, its last argument)
    being drawn: in ``jobs`` forked processes where the platform forks, while this process does
    something else, or here at :meth:`wait`.

    A forked child copies only the thread that forked; it draws with matplotlib (imported, with
    its fonts loaded, before the fork: nothing is imported or pickled again) and writes its files,
    which no other thread of this process does, so it needs no lock another thread may hold."""

    def __init__(self, calls: list[tuple], jobs: int = 1):
        import multiprocessing

        self.calls = calls
        self.children = []
        jobs = min(jobs, len(calls))
        if jobs >= 2 and "fork" in multiprocessing.get_all_start_methods():
            context = multiprocessing.get_context("fork")
            self.children = [context.Process(target=_render_share, args=(calls, start, jobs), daemon=True)
                             for start in range(jobs)]
            for child in self.children:
                child.start()

    def wait(self) -> list[Path]:
        """The paths written, once every figure is."""
        if not self.children:
            return [call[0](*call[1:]) for call in self.calls]
        for child in self.children:
            child.join()
        failed = [child.exitcode for child in self.children if child.exitcode != 0]
        if failed:
            raise RuntimeError(f"figure writing failed in {len(failed)} of {len(self.children)} processes "
                               f"(exit codes {failed})")
        return [call[-1] for call in self.calls]


def _render_share(calls: list[tuple], start: int, stride: int) -> None:
    import os
    import traceback

    try:
        for call in calls[start::stride]:
            call[0](*call[1:])
    except BaseException:  # noqa: BLE001 - reported through the exit code
        traceback.print_exc()
        os._exit(1)
    os._exit(0)  # no interpreter teardown in a forked child: the parent owns every resource
