"""The onset of an elevator loss as a transient of a closed tube set, and its lower bound."""
