"""VQ-PAE (WalkTheDog, Li et al. 2024): a phase manifold shared by characters of any skeleton."""

__version__ = "0.1.0"
