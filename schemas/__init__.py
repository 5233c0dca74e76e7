"""Message and report schemas, installed as package data of ``imupipe.schemas``."""
