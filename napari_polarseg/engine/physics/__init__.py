"""Physics of the polarisation stack: from raw frames to the polarisation image.

Demosaicking of polariser-grid (and colour) sensors (:mod:`.mosaic`, :mod:`.colour_mosaic`),
frame registration (:mod:`.registration`), the per-pixel sinusoid fit Î, ρ, φ and the pixel
mask (:mod:`.polarimage`), Stokes components (:mod:`.stokes`) and the Fresnel relations
between degree of polarisation and zenith angle (:mod:`.fresnel`).
"""
