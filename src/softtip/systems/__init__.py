"""The systems softtip implements, one folder each; a system imports the toolkit, never another system."""
