"""softtip's private core: what every stage shares and no stage owns."""
