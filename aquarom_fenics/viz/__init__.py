"""Pictures: plots, renders and animations."""
