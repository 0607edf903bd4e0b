"""What a phone sends (the browser page's JSON, the Sensor Logger app's push) -> ImuBatch messages. Pure."""
