"""posecons: scale-consistent self-supervised monocular depth and ego-motion (Suri, SCIA 2023)."""

__version__ = "0.1.0"
