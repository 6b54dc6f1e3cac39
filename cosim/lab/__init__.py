"""Virtual laboratory tests built on the DEM (docs/design.md §3): the direct shear box,
its servo, measurements, reports and test series."""
