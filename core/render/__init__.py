"""Rendering with Mitsuba 3: scene assembly from arrays, the variant, denoising, orbit cameras, export."""
