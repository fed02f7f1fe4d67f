"""The HTTP service: FastAPI app factory (:func:`service.api.app.create_app`), routers, problem
details, settings and the uvicorn runner (:func:`service.api.server.serve`)."""
