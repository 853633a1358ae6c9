"""Measured and data-driven BRDFs: MERL tables from the shared neural fits, the PCA basis (Nielsen et al. 2015), reconstruction from sparse observations."""
