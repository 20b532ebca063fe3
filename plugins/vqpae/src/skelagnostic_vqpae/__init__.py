"""VQ-PAE (WalkTheDog, Li et al. 2024): a phase manifold shared by characters of any skeleton."""

from skelagnostic.version import distribution_version

#: Version of the distribution that ships this plugin (built-in: skelagnostic's).
__version__ = distribution_version("skelagnostic")
