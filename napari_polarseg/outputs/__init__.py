"""What the package writes: result folders and figures."""
