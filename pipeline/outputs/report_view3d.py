"""The "3D views" section of ``report.html``: the pictures :mod:`pipeline.outputs.view3d` drew.

Kept apart from :mod:`pipeline.outputs.report` (one section function, the last section).
"""

from __future__ import annotations

from pipeline.outputs.report_html import img, para

__all__ = ["view3d_section"]


def view3d_section(pictures: list[tuple[bytes, str]] | None) -> str:
    """The section's HTML: each ``(png, alt)`` picture, and what the pictures show.

    ``pictures``: None when the run left the views out (``run.views = false``); empty when
    they could not be rendered (the run's log says why). The section then says which.
    """
    head = "<h2 id='view3d'>11. 3D views</h2>"
    if pictures is None:
        return head + para("The 3D views were left out of this run (run.views = false).")
    if not pictures:
        return head + para(
            "The 3D views were not rendered in this run (see the run's log for the warning); "
            "the .vtp files in view/ hold the scene where they were written."
        )
    text = (
        "The true seabed (sand, translucent) and water surface (blue, translucent), a few "
        "beams (orange: the air ray, cut short, to the pulse's surface point, then the "
        "refracted ray to its bottom point) and the class-40 points, coloured first by their "
        "depth error against the truth (blue too shallow, red too deep), then by their "
        "propagated uncertainty (TPU, one sigma of z). The vertical exaggeration is in the "
        "picture. view/*.vtp holds the same scene for ParaView; `bathy view OUT` opens it."
    )
    return head + "".join(img(png, alt) for png, alt in pictures) + para(text)
