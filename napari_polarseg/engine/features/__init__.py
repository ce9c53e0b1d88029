"""Features of the polarisation image.

Block spherical-harmonic coefficients (:mod:`.harmonics`), block polarisation statistics
(:mod:`.polstats`), their feature vectors, PCA, whitening and Mahalanobis distances
(:mod:`.pca`), and the multi-scale per-pixel features of the pixel classifier
(:mod:`.pixel_features`).
"""
