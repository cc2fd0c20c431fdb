"""Simulated CAN peers (ODrive, CiA 402 drive) and bus fault injection."""
