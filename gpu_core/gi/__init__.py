"""Global illumination [WZPB09], in the order it runs: shading points, the
irradiance cache (sample points, outliers, interpolation), the illumination
cut, final gathering, and the pipeline that chains them on the device."""
