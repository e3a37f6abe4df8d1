"""The irradiance cache [WZPB09]: sample points chosen among the shading
points (samples.py: adaptive seeding, k-means), lone outliers clamped
(outliers.py), and the gathered irradiance interpolated to every shading
point (interpolation.py), all on the device."""

# the programs of the cache stages (for building them up front)
PROGRAMS = tuple((name, {}) for name in (
    "gi/cache/frame.cl", "gi/cache/seeding.cl", "gi/cache/clusters.cl", "gi/cache/grid.cl", "device/primitives.cl"))
