"""Raw OpenStreetMap input: where a region's data comes from and how its roads are read."""
