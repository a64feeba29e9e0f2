"""The sensor models every mode shares: cone templates (which cells a sonar cone covers), the
inverse model of standard mapping and the forward model of EM.
"""
