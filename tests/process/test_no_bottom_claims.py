"""Class-45 claims that a nearby class-40 sounding or ground point contradicts are not made."""

from __future__ import annotations

import numpy as np

from pipeline.process.classify import (
    BATHYMETRIC_POINT,
    GROUND,
    NO_BOTTOM_FOUND_AT,
    ClassifySettings,
)
from pipeline.process.returns import Points, ReturnKind
from pipeline.process.survey_points import contradicted_claims
from tests.test_evaluate import make_points


def _points(xy, depth, cls, kind=ReturnKind.BOTTOM):
    depth = np.asarray(depth, dtype=np.float64)
    pts = make_points(np.column_stack([xy, -depth]), depth, [cls] * len(depth))
    return pts.replace(kind=np.full(len(depth), kind, np.uint8))


def test_claims_deeper_than_a_near_sounding_are_found_as_brute_force_finds_them():
    # soundings on a 1:10 slope (depth = x / 10) with 0.2 m noise, a few gaps; claims anywhere
    # at depths around the slope's: the reference tests every claim against every sounding
    rng = np.random.default_rng(4)
    xy = rng.uniform(0.0, 100.0, (3000, 2))
    keep = ~((xy[:, 0] > 40.0) & (xy[:, 0] < 55.0))  # a strip with no sounding
    xy = xy[keep]
    depth = xy[:, 0] / 10.0 + rng.normal(0.0, 0.2, len(xy))
    others = _points(xy[:50], depth[:50], BATHYMETRIC_POINT, ReturnKind.SURFACE)  # not bottoms
    sea = _points(xy[50:], depth[50:], BATHYMETRIC_POINT)
    cxy = rng.uniform(0.0, 100.0, (800, 2))
    cdepth = cxy[:, 0] / 10.0 + rng.uniform(-2.0, 3.0, 800)
    claims = _points(cxy, cdepth, NO_BOTTOM_FOUND_AT)
    st = ClassifySettings(no_bottom_radius_m=3.0, no_bottom_margin_m=0.5)
    got = contradicted_claims(claims, Points.concatenate([others, sea]), st)
    d2 = ((cxy[:, None, :] - xy[None, 50:, :]) ** 2).sum(axis=2)
    near = d2 <= 3.0**2
    shallowest = np.where(near, depth[None, 50:], np.inf).min(axis=1)
    want = cdepth > shallowest + 0.5
    np.testing.assert_array_equal(got, want)
    assert 50 < want.sum() < 750  # some of both
    assert not got[(cxy[:, 0] > 43.0) & (cxy[:, 0] < 52.0)].any()  # nothing near: no test


def test_no_radius_no_test_and_no_soundings_no_test():
    claims = _points(np.zeros((3, 2)), np.array([5.0, 6.0, 7.0]), NO_BOTTOM_FOUND_AT)
    sea = _points(np.zeros((1, 2)), np.array([1.0]), BATHYMETRIC_POINT)
    assert contradicted_claims(claims, sea, ClassifySettings()).all()
    off = ClassifySettings(no_bottom_radius_m=0.0)
    assert not contradicted_claims(claims, sea, off).any()
    empty = sea.select(np.zeros(1, bool))
    assert not contradicted_claims(claims, empty, ClassifySettings()).any()
    assert contradicted_claims(claims.select(np.zeros(3, bool)), sea, ClassifySettings()).size == 0


def test_land_contradicts_a_claim_as_a_sounding_does():
    # a shore: ground points (class 2, depth negative: above the water) for x < 0, claims at
    # 0.3-4 m for x > 0; a claim within the land radius and deeper than the margin is not
    # made (brute force over every claim and ground point)
    rng = np.random.default_rng(5)
    gxy = np.column_stack([rng.uniform(-20.0, 0.0, 400), rng.uniform(0.0, 50.0, 400)])
    ground = _points(gxy, -rng.uniform(0.0, 2.0, 400), GROUND, ReturnKind.SURFACE)
    cxy = np.column_stack([rng.uniform(0.0, 10.0, 300), rng.uniform(0.0, 50.0, 300)])
    cdepth = rng.uniform(0.3, 4.0, 300)
    claims = _points(cxy, cdepth, NO_BOTTOM_FOUND_AT)
    # (land's own radius, not the soundings')
    st = ClassifySettings(
        no_bottom_radius_m=1.0, no_bottom_land_radius_m=5.0, no_bottom_margin_m=0.5
    )
    got = contradicted_claims(claims, ground, st)
    d2 = ((cxy[:, None, :] - gxy[None, :, :]) ** 2).sum(axis=2)
    shallowest = np.where(d2 <= 25.0, ground.depth_m[None, :], np.inf).min(axis=1)
    np.testing.assert_array_equal(got, cdepth > shallowest + 0.5)
    assert got[cxy[:, 0] > 3.0].any() and not got[cxy[:, 0] > 5.0].any()
    off = ClassifySettings(no_bottom_land_radius_m=0.0)
    assert not contradicted_claims(claims, ground, off).any()
