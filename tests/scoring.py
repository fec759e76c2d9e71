"""Scores of a decoded acquisition, as the demo reports them (shared by the render-tier tests)."""

from simbench.metrics import edge_band, score


def acquisition_scores(acq, result, *, band_px: int) -> dict:
    """Errors off a ``band_px`` band at depth edges (none for 0), completeness over all pixels,
    stripe-order errors against the ground-truth projector column."""
    band = edge_band(acq.gt.depth_m, object_id=acq.gt.object_id, band_px=band_px) if band_px else None
    return score(
        result.depth_m,
        acq.gt,
        camera=acq.scene.rig.camera,
        exclude=band,
        column_px=result.column_px,
        period_px=21,
        detail=True,
    )
