"""fem_blocks: deformable-block masonry with Non-Smooth Contact Dynamics on FEniCSx."""
__version__ = "0.1.0"
