"""A frame's full state, pure numpy: approaches, looks, and a config resolved once into a Scene."""
