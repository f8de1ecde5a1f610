"""Widgets of the operator application."""
