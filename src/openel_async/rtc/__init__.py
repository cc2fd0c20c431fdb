"""RTC component model."""
