"""The only package that imports Mitsuba or Dr.Jit: process settings, the frame renderer, tone mapping."""
