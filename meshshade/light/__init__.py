"""Light: sources (beam, directional, point), their text specs, entry samples with Fresnel entry, shadows."""
