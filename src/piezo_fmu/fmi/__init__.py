"""The FMI layer: what makes the core an FMU."""
