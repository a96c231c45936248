"""One reader/validator per file format magfab writes or reads."""
