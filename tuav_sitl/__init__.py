"""tuav_sitl."""
