"""The small rate plots of the fleet page: geometry only (numbers), drawn by the templates."""

from __future__ import annotations

from dataclasses import dataclass

from conformance.lint.fleetview import HISTORY_S, RateView

WIDTH, HEIGHT, PAD = 120, 22, 2
MIN_SPAN_S = 30.0


@dataclass(frozen=True)
class Sparkline:
    """A measured rate over the latest ``HISTORY_S`` seconds at most (x: time, y: Hz from 0 to
    ``top``), and the declared rate as a line; ``off`` when the latest point is off it by more
    than ``tolerance`` (relative)."""

    points: str
    last: tuple[float, float] | None
    """The latest point (drawn as a dot: a single point makes no line)."""
    declared_y: float | None
    top: float
    off: bool
    width: int = WIDTH
    height: int = HEIGHT


def sparkline(rate: RateView, now: float | None, tolerance: float = 0.2) -> Sparkline:
    """The plot of ``rate`` at traffic time ``now`` (Unix seconds)."""
    values = [hz for _, hz in rate.history]
    top = max([*(values or [0.0]), rate.declared or 0.0]) * 1.25 or 1.0
    inner_h = HEIGHT - 2 * PAD

    def y(hz: float) -> float:
        return round(HEIGHT - PAD - inner_h * min(hz, top) / top, 1)

    end = now if now is not None else (rate.history[-1][0] if rate.history else 0.0)
    # The x axis spans what was measured, up to HISTORY_S: a young run is not a dot at the edge.
    span = max(MIN_SPAN_S, min(HISTORY_S, end - rate.history[0][0])) if rate.history else HISTORY_S
    coords = [(round(WIDTH - PAD - (WIDTH - 2 * PAD) * min(end - t, span) / span, 1),
               y(hz)) for t, hz in rate.history]
    points = " ".join(f"{x},{yy}" for x, yy in coords)
    off = bool(rate.declared and rate.measured is not None
               and abs(rate.measured - rate.declared) > tolerance * rate.declared)
    return Sparkline(points, coords[-1] if coords else None,
                     y(rate.declared) if rate.declared else None, top, off)
