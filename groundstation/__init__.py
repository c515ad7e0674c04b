"""groundstation."""
