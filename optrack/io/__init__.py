"""Reading and writing files: point clouds (PCD), depth images, atomic writes."""
