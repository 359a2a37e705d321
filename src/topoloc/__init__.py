"""topoloc: map-based geolocalization from motion on OpenStreetMap road graphs."""

__version__ = "0.1.0"
