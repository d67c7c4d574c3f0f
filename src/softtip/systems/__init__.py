"""The systems softtip implements, one folder each, built on the shared toolkit; systems never import each other."""
