"""The irradiance cache [WZPB09]: sample points chosen among the shading
points (samples.py: adaptive seeding, k-means), lone outliers and the
samples' distances clamped by their neighbours' (neighbours.py), and the
gathered irradiance interpolated to every shading point
(interpolation.py), all on the device."""
