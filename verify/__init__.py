"""Compare a re-rendered camera view with the photo: region, heatmaps, verdict."""
